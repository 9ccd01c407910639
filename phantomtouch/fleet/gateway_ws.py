"""The gateway's WebSocket ``/ws``: the service's protocol with an ``armband`` field.

``down``, ``move``, ``up`` and ``play`` name the armband they are for (``play`` may also
carry ``start_at_unix_s``); ``stop`` stops one job (``armband`` and ``job_id``), one
armband (``armband``) or every armband the token may address. ``hello`` is answered
with the armbands online, ``ping`` with ``pong``. ``down`` is a request the armband
answers, and so are ``move`` and ``up`` when they carry an ``id``; without one they are
published (the latest position wins, nothing queues).

``subscribe`` (``rate_hz`` 0–120, 0 stops; optional ``armband``) pushes ``state``
messages at that rate: each armband the token may address (or the one named), with its
status and load as its last heartbeat reported them (the gateway's view of the registry,
so as fresh as the heartbeats).

The session is a thin adapter, as every input of a service is
(:mod:`phantomtouch.service.admission`): the connection is a slot of the gateway's
:class:`~phantomtouch.service.admission.Slots` (kind ``fleet-gateway``), which checks each
message's size and rate against the row and makes room for a newcomer when the slots are
full. What the client holds is held by the armbands' nodes alone: each message is
forwarded with the connection's owner and the client's principal
(:func:`~phantomtouch.fleet.requests.request_principal`), and each node's admission holds
the contacts, their deadline and the shares among principals. Nothing here renews the
client on its behalf: a message renews it on the armband it is sent to, and the client's
``ping`` on every armband it has addressed; when it goes silent the nodes release its
contacts, and when it closes the gateway tells those armbands to release them at once.
When a node lets go of the client's contacts (its silence, a stop, a quota) it says so on
its armband's subject for the connection (:func:`~phantomtouch.fleet.subjects.released`),
and the client is sent ``released`` with the ``armband``, as the service's ``/ws`` sends
it.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import time
from typing import TYPE_CHECKING, Any, Final

from pydantic import ValidationError
from starlette.websockets import WebSocket, WebSocketDisconnect

from phantomtouch.errors import PhantomTouchError, ProtocolError
from phantomtouch.fleet import subjects
from phantomtouch.fleet.auth import Grant
from phantomtouch.fleet.errors import NoNodeError
from phantomtouch.fleet.records import StopScope
from phantomtouch.fleet.requests import pop_start_at_unix_s, request_principal, request_token
from phantomtouch.fleet.subjects import check_name
from phantomtouch.service.connections import is_loopback_address
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_TRY_AGAIN_LATER,
    WS_CLOSE_UNSUPPORTED_DATA,
    Problem,
    SourcesFullError,
    TooLargeError,
    describe,
)
from phantomtouch.service.ws_messages import PROTOCOL_VERSION, MessageError, parse
from phantomtouch.service.ws_sending import GONE, JsonSender
from phantomtouch.service.ws_yield import MAX_REASON_CHARS, ServingTask

if TYPE_CHECKING:
    from phantomtouch.fleet.gateway import Gateway
    from phantomtouch.service.admission import Slot

logger = logging.getLogger("phantomtouch.fleet")

KIND: Final = "fleet-gateway"
"""The gateway's row of the policy table."""
_CONNECTIONS = itertools.count()


class GatewaySession:
    """One client connection to the gateway; :meth:`run` returns when it is closed.
    Every method runs on the gateway's event loop unless its docstring says otherwise."""

    def __init__(self, websocket: WebSocket, gateway: Gateway) -> None:
        self.websocket = websocket
        self.gateway = gateway
        self.owner = f"gw-{gateway.id}-{next(_CONNECTIONS)}"
        self.principal = ""
        self.addressed: set[str] = set()
        """The armbands this connection sent a message to: where its ``ping`` and, when it
        goes, its ``release`` are sent (what it holds there, the node knows)."""
        self.grant: Grant | None = None
        self.sender = JsonSender(websocket)
        self._state_task: asyncio.Task[None] | None = None
        self._serving = ServingTask()

    async def run(self) -> None:
        """Accept, check the token, take a slot, serve frames until the connection ends;
        then free the slot and release what the client held on every armband."""
        await self.websocket.accept()
        self.grant = self.gateway.grants.grant(request_token(self.websocket))
        code: int | None = None
        reason = ""
        slot: Slot | None = None
        listening: Any = None
        try:
            if self.grant is None:
                code, reason = (
                    WS_CLOSE_POLICY_VIOLATION,
                    "a token is required: ?token=... or Bearer",
                )
            else:
                self._serving.start()
                slot = self._open()
                subject = subjects.released_to(self.owner)
                assert subject is not None  # gw-ID-N is one token
                listening = await self.gateway.nc.subscribe(subject, cb=self._released)
                code, reason = await self._serve(slot)
        except SourcesFullError as exc:
            code, reason = WS_CLOSE_TRY_AGAIN_LATER, str(exc)[:MAX_REASON_CHARS]
        except asyncio.CancelledError as cancelled:
            code, reason = self._serving.close_frame(cancelled)
        except (WebSocketDisconnect, OSError):
            pass
        finally:
            self._subscribe(0.0, None)
            if listening is not None:
                with contextlib.suppress(Exception):  # NATS is gone: so is the subscription
                    await listening.unsubscribe()
            if slot is not None:
                slot.close()
            await self._release_all()
        if code is not None:
            with contextlib.suppress(*GONE):
                await self.websocket.close(code, reason)

    def _open(self) -> Slot:
        """The connection's slot (one yields to it when they are full).

        Raises
        ------
        SourcesFullError
            Every slot is held by connections that may not yield (1013).
        """
        self.principal = request_principal(self.websocket, checked=not self.gateway.grants.open)
        peer = self.websocket.client
        return self.gateway.slots.open(
            KIND,
            self.owner,
            principal=self.principal,
            on_yield=self._serving.yield_slot,
            local=is_loopback_address(None if peer is None else peer.host),
        )

    async def _released(self, msg: Any) -> None:
        """A node let go of this connection's contacts on its armband (the watchdog, a
        stop, a quota): ``released`` with the ``armband``, as the service's ``/ws`` tells
        its client (docs/fleet.md)."""
        try:
            notice = json.loads(msg.data)
            message = {
                "type": "released",
                "armband": subjects.released_armband(msg.subject),
                "reason": str(notice["reason"]),
                "contacts": [str(contact) for contact in notice["contacts"]],
            }
        except (ValueError, KeyError, TypeError):
            logger.warning("fleet: a release notice that does not read: %r", msg.data[:200])
            return
        await self.sender.send_unless_gone(message)

    async def _serve(self, slot: Slot) -> tuple[int, str]:
        limit = slot.policy.max_message_bytes
        while True:
            frame = await self.websocket.receive()
            if frame["type"] == "websocket.disconnect":
                raise WebSocketDisconnect(frame.get("code", 1000))
            text = frame.get("text")
            if text is None:
                return WS_CLOSE_UNSUPPORTED_DATA, "binary frames are not supported; send JSON text"
            try:
                verdict = slot.receive(len(text) if 4 * len(text) <= limit else len(text.encode()))
            except TooLargeError:
                return WS_CLOSE_MESSAGE_TOO_BIG, f"message over the limit of {limit} bytes"
            if verdict.admitted:
                await self._handle(text)
            elif verdict.sustained:
                return WS_CLOSE_POLICY_VIOLATION, "over the message rate limit"
            elif verdict.flood_started:
                await self.sender.error(Problem(429, "rate_limited", verdict.reason), None)

    async def _handle(self, text: str) -> None:
        message_id: Any = None
        try:
            data = json.loads(text)
            if not isinstance(data, dict):
                raise ProtocolError("expected a JSON object with a 'type'")
            message_id = data.get("id")
            armband = data.pop("armband", None)
            if armband is not None:
                check_name("armband", armband)
                assert self.grant is not None
                self.grant.check(armband)
            start_at_unix_s = pop_start_at_unix_s(data) if data.get("type") == "play" else None
            message = parse(json.dumps(data))
            await self._dispatch(message.type, data, armband, start_at_unix_s, message_id)
        except ValueError as exc:
            if isinstance(exc, ValidationError):
                await self.sender.error(describe(exc), message_id)
            else:
                await self.sender.error(
                    Problem(422, "invalid_json", f"the frame is not JSON: {exc}"), None
                )
        except MessageError as exc:
            await self.sender.error(exc.problem, exc.message_id)
        except PhantomTouchError as exc:
            await self.sender.error(describe(exc), message_id)

    @staticmethod
    def _need(armband: str | None, kind: str) -> str:
        if armband is None:
            raise ProtocolError(f"armband: field required for {kind} through a gateway")
        return armband

    async def _dispatch(
        self,
        kind: str,
        data: dict[str, Any],
        armband: str | None,
        start_at_unix_s: float | None,
        message_id: Any,
    ) -> None:
        client = self.gateway.client
        if kind == "hello":
            records = self.gateway.registry.online()
            assert self.grant is not None
            await self.sender.send(
                {
                    "type": "welcome",
                    "protocol": PROTOCOL_VERSION,
                    "gateway": self.gateway.id,
                    "watchdog_s": self.gateway.slots.policy(KIND).deadline_s,
                    "unix_time_s": time.time(),
                    "armbands": self.grant.within(r.armband for r in records),
                    "id": message_id,
                }
            )
        elif kind == "ping":
            await self._to_addressed({"type": "ping"})
            await self.sender.send({"type": "pong", "unix_time_s": time.time(), "id": message_id})
        elif kind == "play":
            target = self._need(armband, "play")
            self.addressed.add(target)
            touch = {k: v for k, v in data.items() if k not in ("type", "id")}
            answer = await self.gateway.touch(
                target, touch, start_at_unix_s, self.owner, self.principal
            )
            await self._answer(answer.status, answer.body, message_id)
        elif kind == "down" or (kind in ("move", "up") and message_id is not None):
            target = self._need(armband, kind)
            self.addressed.add(target)
            try:
                answer = await client.contact_request(target, self._forwarded(data))
            except NoNodeError:
                await self.gateway.online(target)
                raise
            if answer.status >= 400:
                error = answer.body.get("error", {})
                error["message"] = f"armband={target!r}: {error.get('message', 'refused')}"
            await self._answer(answer.status, None, message_id, answer.body)
        elif kind in ("move", "up"):
            target = self._need(armband, kind)
            self.addressed.add(target)
            await client.contact(target, self._forwarded(data))
        elif kind == "stop":
            await self._stop(armband, data.get("job_id"), message_id)
        elif kind == "subscribe":
            self._subscribe(float(data["rate_hz"]), armband)
            await self.sender.ok(message_id)
        else:
            raise ProtocolError(f"type={kind!r} is not available through a gateway")

    def _subscribe(self, rate_hz: float, armband: str | None) -> None:
        if self._state_task is not None:
            self._state_task.cancel()
            self._state_task = None
        if rate_hz > 0:
            self._state_task = asyncio.create_task(self._stream_state(1.0 / rate_hz, armband))

    async def _stream_state(self, period_s: float, armband: str | None) -> None:
        assert self.grant is not None
        loop = asyncio.get_running_loop()
        due = loop.time()
        while True:
            records = [
                r
                for r in self.gateway.registry.online()
                if self.grant.allows(r.armband) and armband in (None, r.armband)
            ]
            await self.sender.send_unless_gone(
                {
                    "type": "state",
                    "unix_time_s": time.time(),
                    "armbands": [
                        {
                            "armband": r.armband,
                            "site": r.site,
                            "status": r.status,
                            "load": r.load.model_dump(),
                            "unix_time_s": r.unix_time_s,
                            "clock_offset_s": r.clock_offset_s,
                        }
                        for r in records
                    ],
                }
            )
            due = max(due + period_s, loop.time())
            await asyncio.sleep(due - loop.time())

    async def _stop(self, armband: str | None, job_id: str | None, message_id: Any) -> None:
        assert self.grant is not None
        if job_id is not None:
            target = self._need(armband, "stop of a job_id")
            try:
                answer = await self.gateway.client.stop_job(target, job_id)
            except NoNodeError:
                await self.gateway.online(target)
                raise
            await self._answer(answer.status, answer.body, message_id)
            return
        scope = StopScope() if armband is None else StopScope(scope="armband", armband=armband)
        result = await self.gateway.stop(scope, self.grant)
        await self._answer(200, result, message_id)

    async def _answer(
        self, status: int, result: Any, message_id: Any, error_body: dict[str, Any] | None = None
    ) -> None:
        body = error_body if error_body is not None else result
        if status >= 400:
            error = body.get("error", {}) if isinstance(body, dict) else {}
            problem = Problem(
                status,
                error.get("code", "invalid"),
                error.get("message", ""),
                error.get("fields", []),
            )
            await self.sender.error(problem, message_id)
        else:
            await self.sender.ok(message_id, result)

    def _forwarded(self, data: dict[str, Any]) -> dict[str, Any]:
        """A client's contact message as its armband's node takes it: with the connection's
        owner and the client's principal."""
        return {**data, "owner": self.owner, "principal": self.principal}

    async def _to_addressed(self, message: dict[str, Any]) -> None:
        """Publish ``message`` (a ``ping`` or a ``release``) of this connection to every
        armband it has addressed; an armband gone meanwhile is skipped."""
        for armband in sorted(self.addressed):
            with contextlib.suppress(Exception):
                await self.gateway.client.contact(armband, self._forwarded(message))

    async def _release_all(self) -> None:
        """The client went: every armband it addressed lets go of its contacts at once."""
        await self._to_addressed({"type": "release"})
        self.addressed.clear()
