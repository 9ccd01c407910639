"""Closed routes: a node or gateway refuses a cluster whose route port admits anyone.

A NATS server listens on a route port for the other servers of its cluster. Without
route authorization any server that reaches that port joins the cluster, and what its
own (anonymous) clients publish reaches every armband, past every user's permissions.
Before it joins, ``serve --fleet`` and ``gateway`` read the greeting of each route port
named with ``--fleet-routes`` (the ``INFO`` line a server sends on connection, which says
``auth_required``) and refuse to start (exit 2, one line) when one admits a server without
credentials, unless told ``--fleet-insecure`` / ``--insecure-nats``. Without
``--fleet-routes``, or when a route port does not answer, they say in one line that they
cannot tell and go on. ``phantomtouch fleet-config`` writes route authorization.
"""

from __future__ import annotations

import json
import socket
from typing import Any
from urllib.parse import urlsplit

from phantomtouch.errors import ParameterError

GREETING_BYTES = 4096
"""Longest ``INFO`` line read from a port."""


def _address(url: str, default_port: int) -> tuple[str, int]:
    parts = urlsplit(url if "://" in url else f"nats-route://{url}")
    if not parts.hostname:
        raise ParameterError(f"{url!r} must be HOST:PORT or nats-route://HOST:PORT")
    return parts.hostname, parts.port or default_port


def greeting(url: str, *, default_port: int, timeout_s: float) -> dict[str, Any] | None:
    """The ``INFO`` a NATS port sends on connection, or None (no answer, not NATS)."""
    try:
        with socket.create_connection(_address(url, default_port), timeout=timeout_s) as sock:
            data = b""
            while b"\r\n" not in data and len(data) < GREETING_BYTES:
                chunk = sock.recv(GREETING_BYTES)
                if not chunk:
                    break
                data += chunk
    except OSError:
        return None
    line = data.split(b"\r\n", 1)[0]
    if not line.startswith(b"INFO "):
        return None
    try:
        info = json.loads(line[5:])
    except ValueError:
        return None
    return info if isinstance(info, dict) else None


def check_routes(
    servers: list[str], routes: list[str], flag: str, *, timeout_s: float = 2.0
) -> str | None:
    """Refuse open route ports; None when every route port named is closed (or the
    server is not part of a cluster), else the one line saying what cannot be told.

    Raises
    ------
    ParameterError
        A route port in ``routes`` admits a server without credentials.
    """
    if not routes:
        info = greeting(servers[0], default_port=4222, timeout_s=timeout_s)
        if info is None or not info.get("cluster"):
            return None
        return (
            f"fleet: cannot tell whether the route ports of cluster {info['cluster']!r} admit "
            "a server without credentials; name them with --fleet-routes HOST:PORT,... to check"
        )
    silent = []
    for route in routes:
        info = greeting(route, default_port=6222, timeout_s=timeout_s)
        if info is None:
            silent.append(route)
        elif not info.get("auth_required"):
            raise ParameterError(
                f"fleet: the route port {route} admits a server without credentials, so "
                "anyone who reaches it joins the cluster and plays on every armband; close it "
                "(phantomtouch fleet-config writes route authorization, docs/fleet.md) or start "
                f"with {flag}"
            )
    if silent:
        return (
            f"fleet: cannot tell whether {', '.join(silent)} admits a server without "
            "credentials: no NATS route port answers there"
        )
    return None
