"""The gateway's WebSocket ``/ws``: the service's protocol with an ``armband`` field.

``down``, ``move``, ``up`` and ``play`` name the armband they are for (``play`` may also
carry ``start_at_unix_s``); ``stop`` stops one job (``armband`` and ``job_id``), one
armband (``armband``) or every armband the token may address. ``hello`` is answered
with the armbands online, ``ping`` with ``pong``. Contacts are tracked here per
(armband, contact), so a step their state does not allow is answered with ``error`` as
on an armband's own ``/ws``; ``down`` is a request the armband answers, ``move`` and
``up`` are published (the latest position wins, nothing queues).

``subscribe`` (``rate_hz`` 0–120, 0 stops; optional ``armband``) pushes ``state``
messages at that rate: each armband the token may address (or the one named), with its
status and load as its last heartbeat reported them (the gateway's view of the registry,
so as fresh as the heartbeats).

While the client talks, the gateway pings every armband it holds contacts on; when it
goes silent for ``watchdog_s`` or disconnects, the gateway releases them, and if the
gateway itself vanishes the armbands' own fleet watchdog does.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import time
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError
from starlette.websockets import WebSocket, WebSocketDisconnect

from phantomtouch.errors import PhantomTouchError, ProtocolError
from phantomtouch.fleet.auth import Grant
from phantomtouch.fleet.errors import NoNodeError
from phantomtouch.fleet.records import StopScope
from phantomtouch.fleet.requests import pop_start_at_unix_s, request_token
from phantomtouch.fleet.subjects import check_name
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_UNSUPPORTED_DATA,
    Problem,
    describe,
)
from phantomtouch.service.flood import FloodGuard
from phantomtouch.service.ws_messages import PROTOCOL_VERSION, MessageError, parse
from phantomtouch.service.ws_sending import GONE, JsonSender

if TYPE_CHECKING:
    from phantomtouch.fleet.gateway import Gateway

_CONNECTIONS = itertools.count()


class GatewaySession:
    """One client connection to the gateway; :meth:`run` returns when it is closed."""

    def __init__(self, websocket: WebSocket, gateway: Gateway) -> None:
        self.websocket = websocket
        self.gateway = gateway
        self.settings = gateway.settings
        self.owner = f"gw-{gateway.id}-{next(_CONNECTIONS)}"
        self.held: dict[str, set[str]] = {}
        self.last_message_s = time.monotonic()
        self.limiter = FloodGuard(self.settings.ws_messages_per_s)
        self.grant: Grant | None = None
        self.sender = JsonSender(websocket)
        self._state_task: asyncio.Task[None] | None = None

    async def run(self) -> None:
        await self.websocket.accept()
        self.grant = self.gateway.grants.grant(request_token(self.websocket))
        keepalive = asyncio.create_task(self._keepalive())
        code: int | None = None
        reason = ""
        try:
            if self.grant is None:
                code, reason = (
                    WS_CLOSE_POLICY_VIOLATION,
                    "a token is required: ?token=... or Bearer",
                )
            else:
                code, reason = await self._serve()
        except (WebSocketDisconnect, OSError):
            pass
        finally:
            keepalive.cancel()
            self._subscribe(0.0, None)
            await self._release_all()
        if code is not None:
            with contextlib.suppress(*GONE):
                await self.websocket.close(code, reason)

    async def _serve(self) -> tuple[int, str]:
        limit = self.settings.max_ws_message_bytes
        while True:
            frame = await self.websocket.receive()
            if frame["type"] == "websocket.disconnect":
                raise WebSocketDisconnect(frame.get("code", 1000))
            self.last_message_s = time.monotonic()
            text = frame.get("text")
            if text is None:
                return WS_CLOSE_UNSUPPORTED_DATA, "binary frames are not supported; send JSON text"
            if len(text.encode()) > limit:
                return WS_CLOSE_MESSAGE_TOO_BIG, f"message over the limit of {limit} bytes"
            if not self.limiter.admit(self.last_message_s):
                if self.limiter.sustained(self.last_message_s):
                    return WS_CLOSE_POLICY_VIOLATION, "over the message rate limit"
                continue
            await self._handle(text)

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
                    "watchdog_s": self.settings.watchdog_s,
                    "unix_time_s": time.time(),
                    "armbands": self.grant.within(r.armband for r in records),
                    "id": message_id,
                }
            )
        elif kind == "ping":
            await self.sender.send({"type": "pong", "unix_time_s": time.time(), "id": message_id})
        elif kind == "play":
            target = self._need(armband, "play")
            touch = {k: v for k, v in data.items() if k not in ("type", "id")}
            answer = await self.gateway.touch(target, touch, start_at_unix_s, f"{self.owner}")
            await self._answer(answer.status, answer.body, message_id)
        elif kind == "down":
            target = self._need(armband, "down")
            contact = data["contact"]
            if contact in self.held.get(target, set()):
                raise ProtocolError(
                    f"contact={contact!r} is already down on armband {target!r}: expected move "
                    "or up, got down"
                )
            try:
                answer = await client.contact_down(target, {**data, "owner": self.owner})
            except NoNodeError:
                await self.gateway.online(target)
                raise
            if answer.status == 200:
                self.held.setdefault(target, set()).add(contact)
            await self._answer(answer.status, None, message_id, answer.body)
        elif kind in ("move", "up"):
            target = self._need(armband, kind)
            contact = data["contact"]
            if contact not in self.held.get(target, set()):
                raise ProtocolError(
                    f"contact={contact!r} is not down on armband {target!r}: expected down, "
                    f"got {kind}"
                )
            await client.contact(target, {**data, "owner": self.owner})
            if kind == "up":
                self.held[target].discard(contact)
            await self.sender.ok(message_id)
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
        for target in result["stopped"]:
            self.held.pop(target, None)
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

    async def _keepalive(self) -> None:
        """Ping held armbands while the client talks; release them when it goes silent."""
        period_s = self.settings.watchdog_s / 4
        while True:
            await asyncio.sleep(period_s)
            if not self.held:
                continue
            if time.monotonic() - self.last_message_s > self.settings.watchdog_s:
                released = {a: sorted(c) for a, c in self.held.items() if c}
                await self._release_all()
                if released:
                    await self.sender.send_unless_gone(
                        {"type": "released", "reason": "watchdog", "contacts": released}
                    )
                continue
            for armband in list(self.held):
                with contextlib.suppress(Exception):
                    await self.gateway.client.contact(
                        armband, {"type": "ping", "owner": self.owner}
                    )

    async def _release_all(self) -> None:
        held, self.held = self.held, {}
        for armband in held:
            with contextlib.suppress(Exception):
                await self.gateway.client.contact(armband, {"type": "release", "owner": self.owner})
