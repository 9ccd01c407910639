"""Framed messages over the pipes between the host and the engine process: a pickle
behind its length (4 bytes, big-endian, as :mod:`multiprocessing.connection` frames it,
so the host sends and receives through its ``Connection``). Neither side waits for the
other (``docs/engine.md``, Transports).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import struct
import sys
import threading
from collections import deque
from typing import Any

_HEADER = struct.Struct("!i")
PIPE_BYTES = 1 << 20
"""Pipe buffer asked for (Linux ``F_SETPIPE_SZ``; the system's ``pipe-max-size``, 1 MB by
default, caps it): a plan crosses in a few reads."""


def encode(message: Any) -> bytes:
    """A message as a frame: its length, then its pickle."""
    payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(len(payload)) + payload


def widen(fd: int) -> None:
    """Ask for a larger pipe buffer (no-op where the system does not offer it: Windows
    has no ``fcntl``, macOS no ``F_SETPIPE_SZ``)."""
    if sys.platform == "win32":
        return
    try:
        import fcntl
    except ImportError:  # a POSIX system's Python built without it
        return
    set_size = getattr(fcntl, "F_SETPIPE_SZ", None)
    if set_size is None:
        return
    with contextlib.suppress(OSError):
        fcntl.fcntl(fd, set_size, PIPE_BYTES)


class FrameReader:
    """Reads frames from a non-blocking pipe, a bounded number of bytes at a time.

    Parameters
    ----------
    fd : int
        The read end; made non-blocking here.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        os.set_blocking(fd, False)
        self._buffer = bytearray()
        self.closed = False

    def fill(self, max_bytes: int) -> None:
        """Read what has arrived, at most ``max_bytes``; sets :attr:`closed` at EOF."""
        try:
            data = os.read(self.fd, max_bytes)
        except BlockingIOError:
            return
        except OSError:
            self.closed = True
            return
        if not data:
            self.closed = True
        self._buffer += data

    def next(self) -> Any | None:
        """The next whole message, or None."""
        buffer = self._buffer
        if len(buffer) < _HEADER.size:
            return None
        (size,) = _HEADER.unpack_from(buffer)
        end = _HEADER.size + size
        if len(buffer) < end:
            return None
        payload = bytes(buffer[_HEADER.size : end])
        del buffer[:end]
        return pickle.loads(payload)

    @property
    def pending_bytes(self) -> int:
        return len(self._buffer)


class NonBlockingWriter:
    """Writes frames into a non-blocking pipe; what does not fit waits for :meth:`flush`.

    Parameters
    ----------
    fd : int
    max_pending_bytes : int
        More waiting than this and new frames are dropped (counted in :attr:`dropped`).
    """

    def __init__(self, fd: int, max_pending_bytes: int = 1 << 20) -> None:
        self.fd = fd
        os.set_blocking(fd, False)
        self._pending = bytearray()
        self._max = max_pending_bytes
        self.dropped = 0
        self.broken = False

    def send(self, message: Any) -> None:
        frame = encode(message)
        if len(self._pending) + len(frame) > self._max:
            self.dropped += 1
            return
        self._pending += frame
        self.flush()

    def flush(self) -> None:
        """Write what the pipe takes now."""
        if not self._pending or self.broken:
            return
        try:
            written = os.write(self.fd, self._pending)
        except BlockingIOError:
            return
        except OSError:
            self.broken = True
            return
        del self._pending[:written]


class Outbox:
    """The host's messages to the engine process, written by a thread of their own.

    Parameters
    ----------
    connection : multiprocessing.connection.Connection
        The write end of the pipe (blocking).
    max_bytes : int
        Most bytes waiting; :meth:`put` refuses more.
    """

    def __init__(self, connection: Any, max_bytes: int = 64 << 20) -> None:
        self._connection = connection
        self._max = max_bytes
        self._frames: deque[bytes] = deque()
        self._bytes = 0
        self._ready = threading.Condition()
        self._closed = False
        self.broken = False
        self._thread = threading.Thread(target=self._run, name="phantomtouch-outbox", daemon=True)
        self._thread.start()

    def put(self, message: Any) -> bool:
        """Queue a message, pickled here (host, the caller's thread); False when the outbox
        is full or closed."""
        frame = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        with self._ready:
            if self._closed or self.broken or self._bytes + len(frame) > self._max:
                return False
            self._frames.append(frame)
            self._bytes += len(frame)
            self._ready.notify()
            return True

    def _run(self) -> None:
        while True:
            with self._ready:
                while not self._frames and not self._closed:
                    self._ready.wait()
                if not self._frames:
                    return
                frame = self._frames.popleft()
            try:
                self._connection.send_bytes(frame)
            except OSError:
                with self._ready:
                    self.broken = True
                    self._frames.clear()
                    self._bytes = 0
                return
            with self._ready:
                self._bytes -= len(frame)

    def close(self, timeout_s: float) -> None:
        """Write what waits (at most ``timeout_s``), stop the thread, close the pipe
        (left open while a write still blocks: it ends when the reader is gone)."""
        with self._ready:
            self._closed = True
            self._ready.notify()
        self._thread.join(timeout_s)
        if not self._thread.is_alive():
            self._connection.close()
