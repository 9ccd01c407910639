"""What a gateway reads off a request besides its body: the token, the client's principal,
the start instant."""

from __future__ import annotations

import math
from typing import Any

from starlette.datastructures import Headers
from starlette.requests import HTTPConnection

from phantomtouch.errors import ParameterError
from phantomtouch.service.admission import principal_for

PRINCIPAL_KIND = "fleet"
"""The kind a gateway's clients' principals are named by: ``fleet:HOST`` for a client of
a gateway without tokens, ``token:DIGEST`` for a client that gave one."""


def request_token(connection: HTTPConnection) -> str | None:
    """The token a request carries: ``Authorization: Bearer``, or ``?token=`` (WebSocket)."""
    header = Headers(scope=connection.scope).get("authorization", "")
    scheme, _, given = header.partition(" ")
    if scheme.lower() == "bearer" and given.strip():
        return given.strip()
    if connection.scope["type"] == "websocket":
        return connection.query_params.get("token")
    return None


def request_principal(connection: HTTPConnection, *, checked: bool) -> str:
    """Who the client of a gateway's request is (host, the event loop): the token it gave
    when the gateway ``checked`` tokens (every request with that token is one principal,
    from any host), else its host (every connection of one host is one principal).
    :func:`~phantomtouch.service.admission.principal_for` makes it; the gateway tells it
    the node with every message it forwards (docs/fleet.md, "Who a client is")."""
    peer = connection.client
    host = None if peer is None else peer.host
    token = request_token(connection) if checked else None
    return principal_for(PRINCIPAL_KIND, host=host, token=token)


def pop_start_at_unix_s(body: dict[str, Any]) -> float | None:
    """Take ``start_at_unix_s`` out of a touch body (checked: a finite number ≥ 0)."""
    value = body.pop("start_at_unix_s", None)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ParameterError(f"start_at_unix_s={value!r}: must be a number, seconds since 1970")
    if value < 0:
        raise ParameterError(f"start_at_unix_s={value!r}: must be at least 0")
    return float(value)
