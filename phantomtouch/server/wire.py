"""uvicorn's protocols, adjusted: JSON for unparsable requests, fair WebSocket reading.

A request uvicorn cannot parse (malformed framing, a request line or a header too long
for its parser) never reaches the app: uvicorn answers it itself, by default with a
plain-text ``400``. :class:`JsonErrorProtocol` answers the same ``400`` with the body of
every other refusal, ``{"error": {"code": "invalid", "message", "fields"}}``.

uvicorn's WebSocket protocol parses everything one socket read brings (up to 256 KB,
some 10,000 small frames of a flooding client) in one callback of the event loop, which
held every other request up for a quarter of a second at a time.
:class:`FairWebSocketProtocol` keeps what it received and parses it a slice at a time,
when the session asks for its next message: the parsing of a connection proceeds at the
pace its session handles messages, and the session yields after each one. When the
session closes, the close frame ends the stream and what the client still sends is
dropped unparsed. A text frame that is not UTF-8 is closed with 1007 as uvicorn does,
but logged in one line instead of a traceback, and counted
(``phantomtouch_ws_refused_frames_total{reason="invalid_utf8"}``).

Ping frames never reach the session, so uvicorn answered every one of them: millions a
second of them held the event loop. Each ping now counts in the connection's rate (its
:class:`~phantomtouch.service.admission.Handle`, which the session puts in the scope
under :data:`~phantomtouch.service.admission.handle.SCOPE_KEY`) as a message does, and
renews the connection as a message does: over the rate it is dropped unanswered
(``reason="ping_over_rate"``), and a connection that stays over its rate is closed with
1008, as a flood of messages is.
"""

from __future__ import annotations

import json
import logging
from typing import TYPE_CHECKING, Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from phantomtouch.service.admission import Handle
from phantomtouch.service.admission.handle import SCOPE_KEY
from phantomtouch.service.errors import Problem
from phantomtouch.service.flood import LimitedLog
from phantomtouch.service.metrics import FRAME_REFUSALS

if TYPE_CHECKING:
    from uvicorn._types import ASGIReceiveEvent, ASGISendEvent


def malformed_body(reason: str) -> bytes:
    """The JSON error body of a request that could not be parsed."""
    message = f"malformed HTTP request: {reason}"
    field = {"field": "request", "value": None, "message": message}
    return json.dumps(Problem(400, "invalid", message, [field]).body()).encode()


class JsonErrorProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol whose parse errors answer the service's error body."""

    def send_400_response(self, msg: str) -> None:
        body = malformed_body(msg.rstrip(".").lower())
        content = [b"HTTP/1.1 400 Bad Request\r\n"]
        for name, value in self.server_state.default_headers:
            content.extend([name, b": ", value, b"\r\n"])
        content.extend(
            [
                b"content-type: application/json\r\n",
                b"content-length: " + str(len(body)).encode("ascii") + b"\r\n",
                b"connection: close\r\n",
                b"\r\n",
                body,
            ]
        )
        self.transport.write(b"".join(content))
        self.transport.close()


WS_CLOSE_INVALID_PAYLOAD = 1007
WS_CLOSE_POLICY_VIOLATION = 1008
_REFUSALS_LOG = LimitedLog(logging.getLogger("phantomtouch.server"), 10.0)
"""Frames refused by the protocol log one line per reason every 10 s at most."""

PARSE_SLICE_BYTES = 4096
"""Most received bytes parsed in one turn of the event loop (some 180 small frames or
680 pings, a few milliseconds)."""


class FairWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol parsing received bytes a slice at a time, on demand.

    Received bytes wait unparsed; :meth:`receive` parses slices until a message is ready
    (or nothing is left). Reading from the socket stays paused while bytes wait, so
    what waits is at most one socket read.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._unparsed = bytearray()
        self._closed_by_the_app = False
        self._parse_pending = False

    async def send(self, message: ASGISendEvent) -> None:
        """As uvicorn's; once the session has closed, the connection is ended at once.

        uvicorn goes on parsing what arrives until the client's close reply, for up to
        10 s: a flooding client would have every frame it had sent parsed meanwhile.
        Here the close frame is followed by the end of the stream (the client learns at
        once that nothing more will come), and what still arrives is dropped unparsed.
        """
        await super().send(message)
        if message["type"] == "websocket.close" and self.close_sent:
            self._closed_by_the_app = True
            self._unparsed.clear()
            self.stop_keepalive()
            if self.transport.can_write_eof():
                self.transport.write_eof()

    def data_received(self, data: bytes) -> None:
        if self._closed_by_the_app:
            return  # the session is over: what arrives is read (no reset) and dropped
        self._unparsed += data
        if self.queue.empty():
            self._parse_until_a_message()
        if self._unparsed and not self.disconnected:
            self.read_paused = True
            self.transport.pause_reading()

    def _parse_until_a_message(self) -> None:
        """Parse one slice; while no message is ready, the next slice waits for the event
        loop's next turn (:meth:`_parse_on`): control frames, which make no message, are
        parsed a slice per turn too."""
        if not self._unparsed or not self.queue.empty() or self.disconnected:
            return
        chunk = bytes(self._unparsed[:PARSE_SLICE_BYTES])
        del self._unparsed[:PARSE_SLICE_BYTES]
        super().data_received(chunk)
        if self._unparsed and self.queue.empty() and not self._parse_pending:
            self._parse_pending = True
            self.loop.call_soon(self._parse_on)

    def _parse_on(self) -> None:
        self._parse_pending = False
        if not self._closed_by_the_app:
            self._parse_until_a_message()
            self._read_more_if_all_parsed()

    async def receive(self) -> ASGIReceiveEvent:
        if self.queue.empty():
            self._parse_until_a_message()
            self._read_more_if_all_parsed()  # what is left is part of a frame at most
        message = await self.queue.get()
        if self.queue.empty():
            self._read_more_if_all_parsed()
        return message

    def send_receive_event_to_app(self) -> None:
        """As uvicorn's, but a text frame that is not UTF-8 is refused in one log line
        (rate-limited, no traceback), counted (``invalid_utf8``) and closed with 1007."""
        if self.curr_msg_data_type == "text" and not self.close_sent:
            data = self.frames[0] if len(self.frames) == 1 else b"".join(self.frames)
            try:
                data.decode()
            except UnicodeDecodeError as exc:
                self.frames = []
                FRAME_REFUSALS["invalid_utf8"] += 1
                _REFUSALS_LOG.warning(
                    "invalid_utf8",
                    f"websocket: a text frame from {self._peer()} is not UTF-8 "
                    f"({exc.reason} at byte {exc.start}); closed with 1007",
                )
                self.conn.send_close(WS_CLOSE_INVALID_PAYLOAD)
                self.handle_parser_exception()
                return
        super().send_receive_event_to_app()

    def handle_ping(self) -> None:
        """As uvicorn's (a pong), if the connection's rate admits the ping; over the rate
        the pong is dropped, and a flood lasting ``close_after_s`` closes with 1008."""
        handle = self.scope.get(SCOPE_KEY) if self.scope else None
        if not isinstance(handle, Handle) or self.close_sent:
            super().handle_ping()
            return
        verdict = handle.receive(0)
        if verdict.admitted:
            super().handle_ping()
            return
        self.conn.data_to_send()  # the pong the parser queued: dropped
        FRAME_REFUSALS["ping_over_rate"] += 1
        if verdict.sustained:
            rate = handle.policy.messages_per_s
            close_after_s = handle.meter.own.close_after_s
            _REFUSALS_LOG.warning(
                "ping_flood",
                f"websocket: {self._peer()} sent pings over {rate:g}/s for "
                f"{close_after_s:g} s; closed with 1008",
            )
            self.conn.send_close(
                WS_CLOSE_POLICY_VIOLATION,
                f"over the message rate limit of {rate:g}/s (pings count)",
            )
            self._unparsed.clear()
            self.handle_parser_exception()

    def _peer(self) -> str:
        client = self.client
        return f"{client[0]}:{client[1]}" if client else "a client"

    def _read_more_if_all_parsed(self) -> None:
        if self.read_paused and not self._unparsed and not self.disconnected:
            self.read_paused = False
            self.transport.resume_reading()
