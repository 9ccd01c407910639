"""What the OSC bridge accepted and what it dropped, and why.

Every received message is counted once: ``accepted``, or dropped for one reason. A
datagram dropped as a whole (not OSC, too deep, ...) counts once. Drops are logged one
line each, at most one line per reason and interval
(:class:`~phantomtouch.service.flood.LimitedLog`).
"""

from __future__ import annotations

import threading

REASONS = (
    "malformed",
    "not_utf8",
    "bad_type_tag",
    "too_deep",
    "bad_bundle_size",
    "unknown_address",
    "bad_arguments",
    "not_finite",
    "out_of_range",
    "flood",
    "refused",
    "failed",
)
"""Why a message is dropped: not OSC or cut short; an address or string that is not
UTF-8; unknown type tags; bundles nested too deep; a bundle element whose declared size
exceeds what follows (:mod:`~phantomtouch.osc.packets`); an address the bridge does not
know; arguments of the wrong type or number; NaN or infinity; a value outside its range;
over the message rate; refused by the engine or the library (a contact quota, an unknown
pattern); its handling failed unexpectedly (logged, the bridge goes on)."""


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
