"""What a gateway reads off a request besides its body: the token, the start instant."""

from __future__ import annotations

import math
from typing import Any

from starlette.datastructures import Headers
from starlette.requests import HTTPConnection

from phantomtouch.errors import ParameterError


def request_token(connection: HTTPConnection) -> str | None:
    """The token a request carries: ``Authorization: Bearer``, or ``?token=`` (WebSocket)."""
    header = Headers(scope=connection.scope).get("authorization", "")
    scheme, _, given = header.partition(" ")
    if scheme.lower() == "bearer" and given.strip():
        return given.strip()
    if connection.scope["type"] == "websocket":
        return connection.query_params.get("token")
    return None


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
