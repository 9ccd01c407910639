"""What the OSC bridge accepted and what it dropped, and why; and what the kernel dropped.

Every received message is counted once: ``accepted``, or dropped for one reason. A
datagram dropped as a whole (not OSC, too deep, ...) counts once. Drops are logged one
line each, at most one line per reason and interval
(:class:`~phantomtouch.service.flood.LimitedLog`).
"""

from __future__ import annotations

import socket
import threading
from pathlib import Path

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


PROC_NET = Path("/proc/net")


def _proc_address(host: str, port: int) -> tuple[str, str]:
    """The ``/proc/net`` file and the local-address column of ``(host, port)``: the
    address's 32-bit words in the host's (little-endian) order, in hex, then the port."""
    if ":" in host:
        packed = socket.inet_pton(socket.AF_INET6, host)
        words = [packed[i : i + 4][::-1] for i in range(0, 16, 4)]
        return "udp6", "".join(w.hex().upper() for w in words) + f":{port:04X}"
    return "udp", socket.inet_aton(host)[::-1].hex().upper() + f":{port:04X}"


def kernel_drops(address: tuple[str, int], proc_net: Path = PROC_NET) -> int | None:
    """Datagrams the kernel dropped for the UDP socket bound to ``address`` because its
    receive buffer was full: they never reached the bridge, so no other count sees them
    (a lift lost this way would leave a contact down until the watchdog).

    Read from the ``drops`` column of ``/proc/net/udp`` (``udp6`` for an IPv6 address);
    None where there is no such file (macOS, Windows) or no socket bound there. Any thread.
    """
    try:
        table, local = _proc_address(*address)
        lines = (proc_net / table).read_text().splitlines()
    except (OSError, ValueError):
        return None
    for line in lines[1:]:
        fields = line.split()
        if len(fields) >= 13 and fields[1] == local:
            return int(fields[12])
    return None
