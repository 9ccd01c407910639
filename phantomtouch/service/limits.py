"""ASGI guards in front of the routes: the token and the request body size.

Both answer with the service's error body (:mod:`phantomtouch.service.errors`). The
WebSocket checks its token itself, after accepting, so that it can close with 1008.
"""

from __future__ import annotations

import hmac
import json
from urllib.parse import parse_qs

from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from phantomtouch.service.errors import Problem, TooLargeError, UnauthorizedError, describe

OPEN_PATHS = frozenset({"/health", "/"})
"""Paths that answer without a token: the liveness probe and the web page, which holds no
data; the page itself sends the token of its URL (``/?token=...``) with every request."""
OPEN_PREFIXES = ("/static/",)
"""Path prefixes that answer without a token: the web page's static files."""


def is_open_path(path: str) -> bool:
    """Whether ``path`` answers without a token (see :data:`OPEN_PATHS`)."""
    return path in OPEN_PATHS or path.startswith(OPEN_PREFIXES)


def token_matches(scope: Scope, token: str) -> bool:
    """Whether the request carries ``token``: ``Authorization: Bearer`` or ``?token=``.

    One guess per request: a request with a Bearer ``Authorization`` header is judged by
    it alone, and one with several Bearer headers or several ``token`` query parameters
    never matches (``?token=wrong&token=right`` is refused). Both sides are
    compared as bytes with ``hmac.compare_digest`` (its time does not depend on where they
    differ; ``str`` with non-ASCII characters it refuses): the header as it came off the
    wire, the query value percent-decoded as UTF-8, the token as UTF-8.
    """
    expected = token.encode()
    bearers = [
        given
        for scheme, _, given in (
            value.partition(" ") for value in Headers(scope=scope).getlist("authorization")
        )
        if scheme.lower() == "bearer"
    ]
    if bearers:
        return len(bearers) == 1 and hmac.compare_digest(
            bearers[0].strip().encode("latin-1"), expected
        )
    if scope["type"] == "websocket":
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        values = query.get("token", [])
        return len(values) == 1 and hmac.compare_digest(values[0].encode(), expected)
    return False


async def send_problem(send: Send, problem: Problem) -> None:
    """Answer an HTTP request with ``problem`` (its status, headers and error body)."""
    body = json.dumps(problem.body()).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    headers += [(k.lower().encode(), v.encode()) for k, v in problem.headers.items()]
    await send({"type": "http.response.start", "status": problem.status_code, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class TokenMiddleware:
    """Refuse HTTP requests without the token with 401 (except :func:`is_open_path`)."""

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app = app
        self.token = token

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] == "http"
            and not is_open_path(scope["path"])
            and not token_matches(scope, self.token)
        ):
            message = "a token is required: send 'Authorization: Bearer <token>'"
            await send_problem(send, describe(UnauthorizedError(message, field="Authorization")))
            return
        await self.app(scope, receive, send)


class BodyLimitMiddleware:
    """Refuse request bodies over ``max_bytes`` with 413, by header or while reading."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    def _message(self, size: str) -> str:
        return f"request body of {size} bytes is over the limit of {self.max_bytes} bytes"

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = Headers(scope=scope).get("content-length")
        if length is not None and length.isdigit() and int(length) > self.max_bytes:
            await send_problem(
                send,
                describe(TooLargeError(self._message(length), field="body", value=int(length))),
            )
            return
        received = 0

        async def limited_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    raise HTTPException(413, self._message(f"more than {self.max_bytes}"))
            return message

        await self.app(scope, limited_receive, send)
