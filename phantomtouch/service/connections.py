"""Whether a peer is this machine: the admission never yields a local scene's WebSocket
connection to a newcomer (``docs/security.md``), since every program of this machine shares
127.0.0.1."""

from __future__ import annotations

import ipaddress


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
