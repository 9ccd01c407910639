"""Caps on concurrent WebSocket connections: in all, and per address off loopback.

Idle connections cost memory (about 60 KB each); without a cap one program could open
thousands. A connection is refused -- accepted, then closed at once with
:data:`~phantomtouch.service.errors.WS_CLOSE_TRY_AGAIN_LATER` (1013) and a reason naming
the cap -- when ``max_ws_connections`` are open, or when its address already has
``max_ws_connections_per_address`` open. A connection from a loopback address is never
refused: every program of this machine shares 127.0.0.1, and a cap must never lock the
local scene out (they still count towards the total, so remote clients are refused
first). The figures are in ``/metrics``: ``phantomtouch_ws_open_connections`` and
``phantomtouch_ws_refused_connections_total{cap}``.
"""

from __future__ import annotations

import ipaddress
import threading


def is_loopback_address(host: str | None) -> bool:
    """Whether a peer address is this machine's (127.0.0.0/8, ::1, or an IPv4-mapped
    loopback); an unknown peer is not."""
    if host is None:
        return False
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped.is_loopback
    return address.is_loopback


class ConnectionCaps:
    """Open WebSocket connections, in all and by address (event loop and any thread).

    Parameters
    ----------
    total : int, >= 1
        ``max_ws_connections``.
    per_address : int, >= 1
        ``max_ws_connections_per_address`` (addresses off loopback only).
    """

    def __init__(self, total: int, per_address: int) -> None:
        self.total = total
        self.per_address = per_address
        self._open: dict[str, int] = {}
        self._count = 0
        self._lock = threading.Lock()

    @property
    def open(self) -> int:
        """Connections open now."""
        return self._count

    def enter(self, host: str | None) -> tuple[str, str] | None:
        """Count a new connection from ``host``, or refuse it: None when admitted, else
        ``(cap, reason)`` with cap ``total`` or ``per_address`` and a reason naming the
        setting; a refused one is not counted."""
        key = host or "unknown"
        with self._lock:
            if not is_loopback_address(host):
                if self._count >= self.total:
                    return "total", (
                        f"{self._count} WebSocket connections are open: at most "
                        f"max_ws_connections={self.total}; retry later"
                    )
                held = self._open.get(key, 0)
                if held >= self.per_address:
                    return "per_address", (
                        f"{held} WebSocket connections are open from this address: at "
                        f"most max_ws_connections_per_address={self.per_address}; retry later"
                    )
            self._open[key] = self._open.get(key, 0) + 1
            self._count += 1
            return None

    def leave(self, host: str | None) -> None:
        """A connection counted by :meth:`enter` closed."""
        key = host or "unknown"
        with self._lock:
            held = self._open.get(key, 0) - 1
            if held > 0:
                self._open[key] = held
            else:
                self._open.pop(key, None)
            self._count -= 1
