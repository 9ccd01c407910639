"""Job ids: 32 hex digits from the system's random source, read in batches.

``uuid.uuid4()`` reads 16 bytes from the system for every id, and that read lets go of the
interpreter lock: under a flood of ``POST /touch`` the thread scheduling each job then waits
for the event loop to hand the lock back, once per touch. One read of
:data:`BATCH_IDS` ids' bytes serves that many jobs; the ids stay as unpredictable as before.
"""

from __future__ import annotations

import os
import threading

from phantomtouch.errors import ParameterError

ID_BYTES = 16
"""Random bytes per id (32 hex digits, as ``uuid4().hex`` has)."""
BATCH_IDS = 256
"""Ids drawn from one read of the system's random source."""


class JobIds:
    """Unpredictable, unrepeated job ids (host, any thread).

    Parameters
    ----------
    batch_ids : int, >= 1
        Ids drawn per read of ``os.urandom``.
    """

    def __init__(self, batch_ids: int = BATCH_IDS) -> None:
        if batch_ids < 1:
            raise ParameterError(f"batch_ids={batch_ids!r} must be >= 1")
        self._batch_bytes = ID_BYTES * batch_ids
        self._pool = b""
        self._at = 0
        self._lock = threading.Lock()

    def next(self) -> str:
        """A new id: 32 lowercase hex digits (any thread)."""
        with self._lock:
            if self._at >= len(self._pool):
                self._pool, self._at = os.urandom(self._batch_bytes), 0
            start = self._at
            self._at += ID_BYTES
            return self._pool[start : self._at].hex()
