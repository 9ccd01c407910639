"""The calls of a WebSocket session: live contacts, play/stop, subscribe, ping, requests.

:class:`SessionCalls` is what a caller asks of :class:`~phantomtouch_client.AsyncSession`
(which makes the session's state and keeps its connection, :mod:`phantomtouch_client.session`).
Requests with an ``id`` (``down``,
``up``, ``play``, ``stop``, ``subscribe``, ``ping``) wait for their reply; an ``error``
reply raises the :class:`~phantomtouch_client.ApiError` of its code. ``move`` carries no
id: it is the newest position, sent and forgotten (latest wins), over the contact lane when
the service offers one (:mod:`phantomtouch_client.lane`); a move sent with
:meth:`~SessionCalls.request` (with an ``id``, waiting for its ``ok``) stays on ``/ws``.
While the session reconnects, requests wait up to ``reply_timeout_s`` for it to come back,
and the contact table it restores is the truth.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Mapping
from typing import Any

from websockets.asyncio.client import ClientConnection
from websockets.exceptions import ConnectionClosed

from phantomtouch_client.connection import PendingReplies, SessionState
from phantomtouch_client.contact import Contact, ContactHelpers
from phantomtouch_client.errors import ApiError, ConnectionLost, ReplyTimeout
from phantomtouch_client.lane import ContactLane
from phantomtouch_client.models import Job, JobId, PatternArg, contact_message, touch_request


class SessionCalls:
    """The calls of :class:`~phantomtouch_client.AsyncSession`, which makes the state
    below; every method runs in the session's event loop."""

    url: str
    reconnect: bool
    reply_timeout_s: float
    state: SessionState
    rtt_s: float | None
    _ws: ClientConnection | None
    lane: ContactLane | None
    _connected: asyncio.Event
    _replies: PendingReplies
    _contacts: dict[str, dict[str, Any]]
    _helpers: ContactHelpers
    _contact_lock: asyncio.Lock
    _subscribed_hz: float
    _last_send: float
    _clock_offset_s: float | None

    @property
    def connected(self) -> bool:
        return self.state is SessionState.CONNECTED

    def server_time_s(self) -> float | None:
        """The server clock now, estimated from the newest ``pong``; ``None`` before one.

        For ``start_at_s``: ``await ws.play(..., start_at_s=ws.server_time_s() + 0.1)``.
        """
        if self._clock_offset_s is None:
            return None
        return time.monotonic() + self._clock_offset_s

    def contact(self, name: str) -> Contact:
        """The helper of contact ``name``: ``down``, then ``move`` once per frame, ``up``."""
        return self._helpers.get(name)

    async def flush(self) -> None:
        """Send the newest pending ``move`` of every contact helper (one frame)."""
        await self._helpers.flush()

    async def down(
        self,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        carrier: Mapping[str, Any] | None = None,
        law: str | None = None,
        normal_velocity_m_s: float | None = None,
    ) -> None:
        """A contact touches down at (``x_cm``, ``y_cm``)."""
        message = contact_message(
            "down",
            contact,
            x_cm=x_cm,
            y_cm=y_cm,
            intensity=intensity,
            carrier=dict(carrier) if carrier is not None else None,
            law=law,
            normal_velocity_m_s=normal_velocity_m_s,
        )
        async with self._contact_lock:
            self._contacts[contact] = message
            try:
                await self._contact_request(message)
            except ApiError:
                self._contacts.pop(contact, None)
                raise

    async def move(
        self, contact: str, x_cm: float, y_cm: float, *, intensity: float | None = None
    ) -> None:
        """The contact's newest position; sent at once, without reply (errors go to
        ``on_error``), over the contact lane when the session has one, else over ``/ws``.
        While reconnecting, only remembered for the contact's return."""
        await self._move(contact, x_cm, y_cm, intensity=intensity, lane=True)

    async def _move(
        self,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        lane: bool,
    ) -> None:
        """:meth:`move`; ``lane`` False keeps it on ``/ws``, in order with what was sent
        there before and after it (a move just before ``up``, or behind restored downs)."""
        message = contact_message("move", contact, x_cm=x_cm, y_cm=y_cm, intensity=intensity)
        tracked = self._contacts.get(contact)
        if tracked is not None:
            tracked["x_cm"], tracked["y_cm"] = x_cm, y_cm
            if intensity is not None:
                tracked["intensity"] = intensity
        if self.connected:
            if not (lane and self.lane is not None and self.lane.send_move(message)):
                await self._send(message)
        elif self.state is SessionState.CLOSED or not self.reconnect:
            raise ConnectionLost(f"cannot move contact {contact!r}: the session is closed")

    async def up(self, contact: str, *, normal_velocity_m_s: float | None = None) -> None:
        """Lift-off: the contact fades out with its release ramp."""
        message = contact_message("up", contact, normal_velocity_m_s=normal_velocity_m_s)
        async with self._contact_lock:
            self._contacts.pop(contact, None)
            await self._contact_request(message)

    async def play(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
        start_in_ms: float | None = None,
        start_at_s: float | None = None,
    ) -> Job:
        """Schedule a touch, as ``POST /touch``; answers the job."""
        body = touch_request(
            pattern,
            preset=preset,
            stored=stored,
            overrides=overrides,
            start_in_ms=start_in_ms,
            start_at_s=start_at_s,
        )
        result = await self.request({"type": "play", **body})
        return Job.model_validate(result)

    async def stop(self, job_id: JobId | None = None) -> Any:
        """Stop one job, or (without ``job_id``) everything of every client, as ``POST /stop``."""
        message: dict[str, Any] = {"type": "stop"}
        if job_id is not None:
            message["job_id"] = job_id
        return await self.request(message)

    async def subscribe(self, rate_hz: float) -> None:
        """Ask for ``state`` messages at ``rate_hz`` (0 stops them); see ``on_state``."""
        await self.request({"type": "subscribe", "rate_hz": rate_hz})
        self._subscribed_hz = rate_hz

    async def ping(self) -> float:
        """Ping the server; answers its clock (``server_time_s``) and updates ``rtt_s``."""
        sent = time.monotonic()
        reply = await self._exchange({"type": "ping"})
        received = time.monotonic()
        server_time_s = float(reply["server_time_s"])
        self.rtt_s = received - sent
        self._clock_offset_s = server_time_s - (sent + received) / 2
        return server_time_s

    async def request(self, message: Mapping[str, Any]) -> Any:
        """Send ``message`` with a fresh ``id`` and answer the ``result`` of its ``ok``."""
        reply = await self._exchange(message)
        return reply.get("result")

    async def _exchange(self, message: Mapping[str, Any]) -> dict[str, Any]:
        await self._wait_connected()
        request_id, future = self._replies.expect()
        try:
            await self._send({**message, "id": request_id})
            # asyncio.timeout, not wait_for: on Python 3.11, wait_for swallows a cancel
            # that comes as the reply does, and a cancelled task would go on
            async with asyncio.timeout(self.reply_timeout_s):
                return await future
        except TimeoutError:
            raise ReplyTimeout(
                f"no reply to {message.get('type')!r} (id {request_id}) "
                f"within {self.reply_timeout_s} s"
            ) from None
        finally:
            self._replies.forget(request_id)

    async def _contact_request(self, message: dict[str, Any]) -> None:
        """``down``/``up``: confirmed while connected; while reconnecting the contact table
        is the truth, and the reconnection puts it back on the server."""
        if self.state is SessionState.RECONNECTING:
            return
        try:
            await self.request(message)
        except ConnectionLost:
            if not self.reconnect or self.state is SessionState.CLOSED:
                raise

    async def _wait_connected(self) -> None:
        if self.connected:
            return
        if self.state is SessionState.CLOSED or self.state is SessionState.IDLE:
            raise ConnectionLost(f"the session is {self.state.value}")
        try:
            async with asyncio.timeout(self.reply_timeout_s):
                await self._connected.wait()
        except TimeoutError:
            raise ConnectionLost(
                f"not reconnected within {self.reply_timeout_s} s ({self.url})"
            ) from None

    async def _send(self, message: Mapping[str, Any]) -> None:
        ws = self._ws
        if ws is None:
            raise ConnectionLost("not connected")
        try:
            await ws.send(json.dumps(message, separators=(",", ":")))
        except ConnectionClosed as exc:
            raise ConnectionLost(f"the connection closed: {exc}") from exc
        self._last_send = time.monotonic()
