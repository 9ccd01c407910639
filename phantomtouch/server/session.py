"""One WebSocket connection of ``/ws``: an explicit state machine (docs/protocol.md).

::

    CONNECTING --accept--> OPEN --client closes / limit broken--> CLOSED
         \\--token missing: accept, close 1008--> CLOSED
    OPEN --its slot yielded to a newcomer: close 1013--> CLOSED
           (:mod:`phantomtouch.service.admission`)

In ``OPEN`` each text frame is parsed and handled at once, in arrival order: ``move``
goes straight to the engine's contact mailbox (latest wins, nothing queues here). Each
contact has its own two states, up and down; a step that its state does not allow is
answered with ``error`` ("expected X, got Y") and the session goes on. Malformed frames
are answered with ``error`` too, frames nested too deeply to read included. Only a
binary frame (1003), a frame over the size limit (1009), a missing token or a message
rate exceeded for a second on end (1008), or the admission giving its slot to a newcomer
(1013: the connection held nothing, or was silent longest) close it.
Messages over the rate are dropped and counted; only the first of a flood is answered.
The loop yields to the event loop after every frame, so that a connection whose frames
are already buffered cannot keep HTTP requests and other connections waiting.

The session is a protocol translation over its source's handle at the admission
(:class:`~phantomtouch.service.admission.Handle`, kind ``ws``): the handle checks each
frame's size and rate and renews the connection's owner; the engine's front holds its
contacts (its owner table, :mod:`phantomtouch.engine.owners`) with a deadline of
``watchdog_s`` that every message of the connection pushes on; silence longer than that
releases them, and the front's ``released`` events (``watchdog``, ``quota``, ``stop``,
``engine gone`` ...) become ``released`` messages. Closing, in any way, releases them all,
and stops every touch the connection played (with its release ramp; its state says
``stopped``, reason ``closed``) but those it asked to be ``detached``: they belong to the
connection's principal (owner ``ws:HOST/detached``, with a quota of their own) and play
on (``docs/owners.md``).
"""

from __future__ import annotations

import asyncio
import enum
import time
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError
from starlette.websockets import WebSocket, WebSocketDisconnect

from phantomtouch.errors import PhantomTouchError, ProtocolError
from phantomtouch.service import tact_library
from phantomtouch.service.admission import Arrival, Handle, principal_for
from phantomtouch.service.admission.handle import SCOPE_KEY
from phantomtouch.service.connections import is_loopback_address
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_TRY_AGAIN_LATER,
    WS_CLOSE_UNSUPPORTED_DATA,
    NotFoundError,
    Problem,
    SourcesFullError,
    TooLargeError,
    describe,
)
from phantomtouch.service.limits import token_matches
from phantomtouch.service.running import Service
from phantomtouch.service.ws_messages import (
    PROTOCOL_VERSION,
    ClientMessage,
    Down,
    Hello,
    MessageError,
    Move,
    Ping,
    Play,
    PlayTact,
    Stop,
    Subscribe,
    Up,
    parse,
)
from phantomtouch.service.ws_sending import GONE, JsonSender
from phantomtouch.service.ws_yield import MAX_REASON_CHARS, ServingTask

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront


class SessionState(enum.Enum):
    CONNECTING = "connecting"
    OPEN = "open"
    CLOSED = "closed"


class SessionClosed(Exception):
    """The session ends: the client left, or the server closes with ``code``."""

    def __init__(self, code: int, reason: str = "") -> None:
        super().__init__(f"{code} {reason}".strip())
        self.code = code
        self.reason = reason


class Session:
    """The protocol of one connection; :meth:`run` returns when it is closed."""

    def __init__(self, websocket: WebSocket, service: Service) -> None:
        self.websocket = websocket
        self.service = service
        self.engine: EngineFront = service.engine
        self.watchdog_s = service.admission.policy("ws").deadline_s
        self.state = SessionState.CONNECTING
        self.sender = JsonSender(
            websocket, sent=lambda kind: service.metrics.ws_messages.labels("out", kind).inc()
        )
        self._state_task: asyncio.Task[None] | None = None
        self._serving = ServingTask()
        self._notices: set[asyncio.Task[None]] = set()
        self._count_in = service.metrics.ws_messages.labels("in", "move")
        self.handle: Handle | None = None
        """The connection's source at the admission, once its token is checked."""

    # -- the state machine -------------------------------------------------------------

    def _expect(self, expected: SessionState, new: SessionState) -> None:
        if self.state is not expected:
            raise ProtocolError(f"expected state {expected.value}, got {self.state.value}")
        self.state = new

    async def run(self) -> None:
        """Accept, check the token, serve frames until the connection ends, close the
        handle (its contacts released, its touches stopped)."""
        await self.websocket.accept()
        self._expect(SessionState.CONNECTING, SessionState.OPEN)
        self.service.metrics.ws_connections.inc()
        self.service.metrics.ws_open.inc()
        loop = asyncio.get_running_loop()

        def released(owner: str, contacts: tuple[str, ...], reason: str) -> None:
            loop.call_soon_threadsafe(self.contacts_released, contacts, reason)

        code: int | None = None
        reason = ""
        try:
            token = self.service.settings.token
            if token is not None and not token_matches(self.websocket.scope, token):
                raise SessionClosed(
                    WS_CLOSE_POLICY_VIOLATION, "a token is required: ?token=... or Bearer"
                )
            self._serving.start()
            handle = self.handle = self._open()
            handle.on_released(released)
            await self._serve(handle)
        except SessionClosed as closed:
            code, reason = closed.code, closed.reason
        except asyncio.CancelledError as cancelled:
            code, reason = self._serving.close_frame(cancelled)
        except (WebSocketDisconnect, OSError):
            pass
        finally:
            self._expect(SessionState.OPEN, SessionState.CLOSED)
            if self.service.lane is not None and self.handle is not None:
                self.service.lane.close(self.handle.owner)  # no lane move after the release
            if self._state_task is not None:
                self._state_task.cancel()
            if self.handle is not None:
                self.handle.close("closed")
            self.service.metrics.ws_open.dec()
        if code is not None:
            try:
                await self.websocket.close(code, reason)
            except GONE:
                return

    def _open(self) -> Handle:
        """The connection's handle at the admission, in a slot (one yields if they are
        full); the protocol's ping frames count in its rate (:mod:`phantomtouch.server.wire`).

        Raises
        ------
        SessionClosed
            1013: every slot is held by connections that may not yield.
        """
        peer = self.websocket.client
        host = None if peer is None else peer.host
        try:
            handle = self.service.admission.open(
                "ws",
                self.service.admission.new_source(),
                principal=principal_for("ws", host=host),
                on_yield=self._on_yield,
                local=is_loopback_address(host),
            )
        except SourcesFullError as exc:
            self.service.metrics.ws_refused.labels("full").inc()
            raise SessionClosed(WS_CLOSE_TRY_AGAIN_LATER, str(exc)[:MAX_REASON_CHARS]) from exc
        self.websocket.scope[SCOPE_KEY] = handle
        return handle

    def _on_yield(self, reason: str) -> None:
        """The admission gave this connection's slot to a newcomer (its handle is closed):
        end the session with 1013 (any thread)."""
        if self._serving.serving:
            self.service.metrics.ws_refused.labels("yielded").inc()
        self._serving.yield_slot(reason)

    async def _serve(self, handle: Handle) -> None:
        receive = self.websocket.receive
        limit = handle.policy.max_message_bytes
        while True:
            frame = await receive()
            if frame["type"] == "websocket.disconnect":
                raise WebSocketDisconnect(frame.get("code", 1000))
            received_s = time.perf_counter()
            text = frame.get("text")
            if text is None:
                raise SessionClosed(
                    WS_CLOSE_UNSUPPORTED_DATA, "binary frames are not supported; send JSON text"
                )
            size = len(text) if 4 * len(text) <= limit else len(text.encode())
            try:
                verdict = handle.receive(size)
            except TooLargeError:
                raise SessionClosed(
                    WS_CLOSE_MESSAGE_TOO_BIG, f"message over the limit of {limit} bytes"
                ) from None
            if verdict.arrival is not None:
                await self._handle_text(handle, text, received_s, verdict.arrival)
            else:
                await self._refuse_rate(handle, verdict.sustained, verdict.flood_started)
            await asyncio.sleep(0)

    async def _refuse_rate(self, handle: Handle, sustained: bool, flood_started: bool) -> None:
        self.service.metrics.ws_dropped.inc()
        limit = handle.policy.messages_per_s
        guard = handle.meter.own
        if sustained:
            self.service.metrics.ws_flood_closes.inc()
            raise SessionClosed(
                WS_CLOSE_POLICY_VIOLATION,
                f"over the message rate limit of {limit:g}/s for "
                f"{guard.close_after_s:g} s; {guard.dropped} messages dropped",
            )
        if flood_started:
            message = (
                f"more than {limit:g} messages per second: messages are dropped, unanswered, "
                f"until the rate falls; over it for {guard.close_after_s:g} s closes "
                "the connection (1008)"
            )
            await self.sender.error(Problem(429, "rate_limited", message), None)

    async def _handle_text(
        self, handle: Handle, text: str, received_s: float, arrival: Arrival
    ) -> None:
        try:
            message = parse(text)
        except MessageError as exc:
            self.service.metrics.ws_messages.labels("in", "invalid").inc()
            await self.sender.error(exc.problem, exc.message_id)
            return
        if isinstance(message, Move):
            self._count_in.inc()
        else:
            self.service.metrics.ws_messages.labels("in", message.type).inc()
        try:
            await self._dispatch(handle, message, received_s, arrival)
        except (PhantomTouchError, ValidationError) as exc:
            await self.sender.error(describe(exc), message.id)

    # -- messages ---------------------------------------------------------------------

    async def _dispatch(
        self, handle: Handle, message: ClientMessage, received_s: float, arrival: Arrival
    ) -> None:
        if isinstance(message, Move):
            handle.move(message.contact, message.x_cm, message.y_cm, intensity=message.intensity)
            self.service.metrics.ws_ingest.observe(time.perf_counter() - received_s)
            await self.sender.ok(message.id)
        elif isinstance(message, Down):
            await self._down(handle, message)
        elif isinstance(message, Up):
            if not handle.up(message.contact, normal_velocity_m_s=message.normal_velocity_m_s):
                raise ProtocolError(
                    f"contact={message.contact!r} is not down: expected down, got up "
                    "(a contact is released by up, the watchdog or stop)"
                )
            await self.sender.ok(message.id)
        elif isinstance(message, Ping):
            await self.sender.send(
                {"type": "pong", "server_time_s": self.engine.server_time_s(), "id": message.id}
            )
        elif isinstance(message, Hello):
            if message.wearer is not None:
                await asyncio.to_thread(
                    self.service.wearer.choose, message.wearer, message.wearer_band, field="wearer"
                )
            await self.sender.send(self._welcome(message))
        elif isinstance(message, Play):
            job = await handle.play(message.request, arrival=arrival, detached=message.detached)
            await self.sender.ok(message.id, job.model_dump())
        elif isinstance(message, PlayTact):
            played = await tact_library.play_tact(
                self.service,
                message.tact,
                message,
                handle=handle,
                arrival=arrival,
                field="tact",
            )
            await self.sender.ok(message.id, played.model_dump())
        elif isinstance(message, Stop):
            await self._stop(message)
        elif isinstance(message, Subscribe):
            self._subscribe(message.rate_hz)
            await self.sender.ok(message.id)

    async def _down(self, handle: Handle, message: Down) -> None:
        if message.carrier is not None and message.carrier.kind != "sine":
            await asyncio.to_thread(handle.prepare_carrier, message.carrier)
        handle.down_as(message)
        await self.sender.ok(message.id)

    async def _stop(self, message: Stop) -> None:
        if message.job_id is None:
            self.service.stop_everything()
        else:
            if self.engine.job_state(message.job_id) is None:
                raise NotFoundError(
                    f"job_id={message.job_id!r} is not a known job",
                    field="job_id",
                    value=message.job_id,
                )
            self.engine.stop(message.job_id)
        await self.sender.ok(message.id)

    def _welcome(self, message: Hello) -> dict[str, Any]:
        device = self.engine.device
        welcome = {
            "type": "welcome",
            "protocol": PROTOCOL_VERSION,
            "server_time_s": self.engine.server_time_s(),
            "watchdog_s": self.watchdog_s,
            "device": {
                "channels": self.engine.channels,
                "sample_rate_hz": self.engine.sample_rate_hz,
                "block_frames": self.engine.block_frames,
                "actuators": [a.model_dump() for a in device.actuators],
            },
        }
        if self.service.lane is not None and self.handle is not None:
            peer = self.websocket.client
            host = None if peer is None else peer.host
            welcome["lane"] = self.service.lane.open(self.handle, host)
        choice = self.service.wearer.choice
        if choice is not None:
            welcome["wearer"] = {"name": choice.name, "band": choice.band}
        if message.id is not None:
            welcome["id"] = message.id
        return welcome

    # -- background tasks ---------------------------------------------------------------

    def _subscribe(self, rate_hz: float) -> None:
        if self._state_task is not None:
            self._state_task.cancel()
            self._state_task = None
        if rate_hz > 0:
            self._state_task = asyncio.create_task(self._stream_state(1.0 / rate_hz))

    async def _stream_state(self, period_s: float) -> None:
        loop = asyncio.get_running_loop()
        due = loop.time()
        while self.state is SessionState.OPEN:
            status = self.engine.status().to_dict()
            await self.sender.send_unless_gone(
                {
                    "type": "state",
                    "server_time_s": self.engine.server_time_s(),
                    "levels": status["levels"],
                    "contacts": [
                        {
                            "contact": c["contact"],
                            "x_cm": c["x_cm"],
                            "y_cm": c["y_cm"],
                            "own": self.handle is not None and c["owner"] == self.handle.owner,
                        }
                        for c in status["active_contacts"]
                    ],
                    "active_voices": status["active_voices"],
                    "underruns": status["underruns"],
                    "output_latency_s": status["output_latency_s"],
                }
            )
            due = max(due + period_s, loop.time())
            await asyncio.sleep(due - loop.time())

    def contacts_released(self, contacts: tuple[str, ...], reason: str) -> None:
        """The engine let go of ``contacts`` of this connection: tell the client (on the
        event loop; the front's ``released`` event is handed here)."""
        if reason == "watchdog":
            self.service.metrics.ws_watchdog_releases.inc()
        if not contacts or self.state is not SessionState.OPEN:
            return
        notice = {"type": "released", "reason": reason, "contacts": sorted(contacts)}
        task = asyncio.get_running_loop().create_task(self.sender.send_unless_gone(notice))
        self._notices.add(task)
        task.add_done_callback(self._notices.discard)
