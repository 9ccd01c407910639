"""What the OSC bridge accepted and what it dropped, and why.

Every received message is counted once: ``accepted``, or dropped for one reason. A
datagram that is not OSC at all counts once as ``malformed``.
"""

from __future__ import annotations

import threading

REASONS = (
    "malformed",
    "unknown_address",
    "bad_arguments",
    "not_finite",
    "out_of_range",
    "flood",
    "refused",
)
"""Why a message is dropped: not OSC; an address the bridge does not know; arguments of
the wrong type or number; NaN or infinity; a value outside its range; over the message
rate; refused by the engine or the library (a contact quota, an unknown pattern)."""


class OscCounters:
    """Thread-safe counts of accepted and dropped messages."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(("accepted", *REASONS), 0)

    def count(self, outcome: str) -> None:
        """One more message with ``outcome`` (``accepted`` or one of :data:`REASONS`)."""
        with self._lock:
            self._counts[outcome] += 1

    @property
    def accepted(self) -> int:
        return self._counts["accepted"]

    @property
    def dropped(self) -> int:
        with self._lock:
            return sum(self._counts[r] for r in REASONS)

    def snapshot(self) -> dict[str, int]:
        """Every count, ``accepted`` and each reason."""
        with self._lock:
            return dict(self._counts)
