"""When an HTTP request arrived, for the stop: the engine's stop count as its headers came.

A request's body is read and checked before its route runs; a large touch takes a few
hundred milliseconds there. A stop sent after the request but before its route ran must void
it all the same (``docs/security.md``: nothing sent before a stop is heard after it), so the
arrival is noted by the outermost middleware, before any body is read, and the routes that
play hand it to their source's handle.
"""

from __future__ import annotations

import time

from starlette.requests import HTTPConnection
from starlette.types import ASGIApp, Receive, Scope, Send

from phantomtouch.service.admission import Arrival
from phantomtouch.service.app_state import app_state
from phantomtouch.service.running import Service

SCOPE_KEY = "phantomtouch.arrival"
"""Where :class:`ArrivalMiddleware` leaves a request's :class:`Arrival` in its ASGI scope."""


class ArrivalMiddleware:
    """Note each HTTP request's :class:`Arrival` in its scope as its headers arrive (the
    event loop; before any other middleware, before the body is read)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            service = getattr(scope["app"].state, "service", None)
            if isinstance(service, Service):
                scope[SCOPE_KEY] = Arrival(service.engine.stop_count, time.monotonic())
        await self.app(scope, receive, send)


def request_arrival(connection: HTTPConnection) -> Arrival:
    """The request's :class:`Arrival` as :class:`ArrivalMiddleware` noted it (now, for an
    app without it). The event loop."""
    arrival = connection.scope.get(SCOPE_KEY)
    if isinstance(arrival, Arrival):
        return arrival
    engine = app_state(connection, "service", Service).engine
    return Arrival(engine.stop_count, time.monotonic())
