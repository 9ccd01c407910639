"""The HTTP protocol's door: a header deadline, a header size limit, the connection budget.

uvicorn waits for a request's headers for as long as the client takes and keeps every
byte of them, and accepts every connection until the process has no file descriptor
left; a crowd of idle or slow clients then keeps everyone out, ``POST /stop`` included.
:func:`guarded_protocol` builds uvicorn's HTTP protocol (:class:`JsonErrorProtocol`)
with three more rules, each answered with the service's JSON error body and counted in
``/metrics`` (``phantomtouch_connections_refused_total{reason}``):

- ``header_timeout``: the headers of a request must have arrived ``header_timeout_s``
  after the connection opened (or after the request's first byte on a kept-alive
  connection); else 408 and the connection is closed;
- ``header_too_large``: a request whose headers pass ``max_header_bytes`` is answered
  431 and closed, its bytes dropped;
- ``budget``: beyond :attr:`ConnectionBudget.connections` open connections (WebSockets
  included) a new connection enters the *stop lane*: it is served only if its request
  is ``POST /stop`` (the token is checked as for any request), within
  :data:`LANE_HEADER_TIMEOUT_S`; any other request is answered 503 and closed. When the
  lane is full, the lane connection that has waited longest for its headers is closed
  to make room (a token holder's ``POST /stop`` arrives whole at once and is served
  before a crowd can push it out); with nothing to close, the newcomer is.

Every rule runs on the event loop, in the protocol's callbacks.
"""

from __future__ import annotations

import asyncio
import json
from collections import OrderedDict
from typing import Any

from phantomtouch.server.wire import JsonErrorProtocol
from phantomtouch.service.descriptors import ConnectionBudget
from phantomtouch.service.errors import ErrorCode, Problem
from phantomtouch.service.metrics import CONNECTION_REFUSALS

LINGER_S = 1.0
"""How long a refused connection is read (and what it sends dropped) before it is closed."""
LINGER_BYTES = 1 << 20
"""How much a refused connection may send before it is closed anyway."""
LANE_HEADER_TIMEOUT_S = 2.0
"""How long a connection of the stop lane may take to send its headers."""
STOP_REQUEST = ("POST", "/stop")

_STATUS_LINES = {
    408: b"HTTP/1.1 408 Request Timeout\r\n",
    431: b"HTTP/1.1 431 Request Header Fields Too Large\r\n",
    503: b"HTTP/1.1 503 Service Unavailable\r\n",
}


def _error_body(status: int, message: str) -> bytes:
    code: ErrorCode = "busy" if status == 503 else "invalid"
    field = {"field": "request", "value": None, "message": message}
    return json.dumps(Problem(status, code, message, [field]).body()).encode()


class _Lane:
    """The connections of the stop lane, oldest first (event loop)."""

    def __init__(self) -> None:
        self.members: OrderedDict[GuardedHttpProtocol, None] = OrderedDict()


class GuardedHttpProtocol(JsonErrorProtocol):
    """:class:`JsonErrorProtocol` with the rules of the module docstring.

    :func:`guarded_protocol` sets the class attributes; uvicorn makes one instance per
    connection.
    """

    budget: ConnectionBudget
    header_timeout_s: float
    max_header_bytes: int
    lane: _Lane

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._in_lane = False
        self._awaiting_headers = True
        self._header_bytes = 0
        self._deadline: asyncio.TimerHandle | None = None
        self._refused = False
        self._linger_bytes = 0

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        served = len(self.connections) - len(self.lane.members)
        super().connection_made(transport)
        if served >= self.budget.connections:
            if len(self.lane.members) >= self.budget.stop_lane and not self._evict_one():
                CONNECTION_REFUSALS["budget"] += 1
                self.transport.abort()
                return
            self._in_lane = True
            self.lane.members[self] = None
        self._arm_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_deadline()
        self.lane.members.pop(self, None)
        super().connection_lost(exc)

    def _evict_one(self) -> bool:
        for member in self.lane.members:
            if member._awaiting_headers:
                CONNECTION_REFUSALS["budget"] += 1
                self.lane.members.pop(member)
                member._refused = True
                member.transport.abort()
                return True
        return False

    def _arm_deadline(self) -> None:
        if self._deadline is None and not self._refused:
            seconds = LANE_HEADER_TIMEOUT_S if self._in_lane else self.header_timeout_s
            self._deadline = self.loop.call_later(seconds, self._headers_late)

    def _disarm_deadline(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _headers_late(self) -> None:
        self._deadline = None
        if self._awaiting_headers and not self._refused:
            seconds = LANE_HEADER_TIMEOUT_S if self._in_lane else self.header_timeout_s
            self._refuse(
                408, "header_timeout", f"the request's headers did not arrive within {seconds:g} s"
            )

    def _refuse(self, status: int, reason: str, message: str) -> None:
        """Answer ``status`` with the error body, count ``reason`` and close: a
        connection of the stop lane at once, any other when the client stops sending,
        once :data:`LINGER_BYTES` more were read and dropped, or after :data:`LINGER_S`
        (closing with the client's bytes unread would reset the connection, and the
        client lose the answer)."""
        CONNECTION_REFUSALS[reason] += 1
        self._refused = True
        self._linger_bytes = LINGER_BYTES
        self._disarm_deadline()
        body = _error_body(status, message)
        self.transport.write(
            b"".join(
                [
                    _STATUS_LINES[status],
                    *(
                        name + b": " + value + b"\r\n"
                        for name, value in self.server_state.default_headers
                    ),
                    b"content-type: application/json\r\n",
                    b"content-length: " + str(len(body)).encode("ascii") + b"\r\n",
                    b"connection: close\r\n\r\n",
                    body,
                ]
            )
        )
        if self._in_lane:  # beyond the budget: its descriptor is wanted at once
            self.lane.members.pop(self, None)
            self.transport.close()
            return
        if self.transport.can_write_eof():
            self.transport.write_eof()
        self._deadline = self.loop.call_later(LINGER_S, self.transport.close)

    def data_received(self, data: bytes) -> None:
        if self._refused:  # answered: read and dropped, up to a point
            self._linger_bytes -= len(data)
            if self._linger_bytes <= 0:
                self.transport.close()
            return
        if self._awaiting_headers:
            self._header_bytes += len(data)
        super().data_received(data)
        if (
            self._awaiting_headers
            and not self._refused
            and self._header_bytes > self.max_header_bytes
        ):
            self._refuse(
                431,
                "header_too_large",
                f"the request's headers are over max_header_bytes={self.max_header_bytes}",
            )

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._awaiting_headers = True
        self._arm_deadline()

    def on_message_complete(self) -> None:
        super().on_message_complete()
        self._awaiting_headers = True  # what comes next is the next request's
        self._header_bytes = 0

    def on_headers_complete(self) -> None:
        self._awaiting_headers = False
        self._header_bytes = 0
        self._disarm_deadline()
        if (
            self._in_lane
            and (self.parser.get_method().decode("ascii", "replace"), self._path()) != STOP_REQUEST
        ):
            self._refuse(
                503,
                "budget",
                f"{self.budget.connections} connections are open, the most this server "
                "serves at once; only POST /stop is served beyond them; retry later",
            )
            return
        super().on_headers_complete()

    def _path(self) -> str:
        import httptools

        try:
            return httptools.parse_url(self.url).path.decode("ascii", "replace")
        except httptools.HttpParserInvalidURLError:
            return ""

    def _should_upgrade(self) -> bool:
        return not self._in_lane and not self._refused and super()._should_upgrade()

    def _unsupported_upgrade_warning(self) -> None:
        if not self._refused:
            super()._unsupported_upgrade_warning()

    def send_400_response(self, msg: str) -> None:
        if not self._refused:
            self._refused = True
            self._disarm_deadline()
            super().send_400_response(msg)


def guarded_protocol(
    budget: ConnectionBudget, *, header_timeout_s: float, max_header_bytes: int
) -> type[GuardedHttpProtocol]:
    """A :class:`GuardedHttpProtocol` class for one server (uvicorn's ``http`` option).

    Parameters
    ----------
    budget : ConnectionBudget
        Connections served, and the stop lane beyond them.
    header_timeout_s : float, > 0
        Longest wait for a request's headers, s.
    max_header_bytes : int, > 0
        Largest request line and headers, bytes.
    """
    return type(
        "GuardedHttpProtocol",
        (GuardedHttpProtocol,),
        {
            "budget": budget,
            "header_timeout_s": header_timeout_s,
            "max_header_bytes": max_header_bytes,
            "lane": _Lane(),
        },
    )
