"""The WebSocket session (asyncio): live contacts, play/stop, subscribe, ping, reconnect.

Life of a session::

    connect() -> hello -> welcome -> CONNECTED --(socket lost)--> RECONNECTING
                                         ^                              |
                                         +-- hello, welcome, contacts --+  (back-off)
    close() from any state -> CLOSED

While connected, a ping loop keeps the server's watchdog fed (a ``ping`` whenever nothing
was sent for a quarter of ``watchdog_s``). When the socket is lost the server releases this
client's contacts; the session reconnects with exponential back-off, says ``hello`` again
and puts every contact that is still down back at its newest position, and re-subscribes.

Requests with an ``id`` (``down``, ``up``, ``play``, ``stop``, ``subscribe``, ``ping``) wait
for their reply; an ``error`` reply raises the :class:`~phantomtouch_client.ApiError` of its
code. ``move`` carries no id: it is the newest position, sent and forgotten (latest wins).
Callbacks (``on_state``, ``on_released``, ``on_error``, ``on_connection``) run in the event
loop and must return quickly.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any, Self

from websockets.asyncio.client import ClientConnection
from websockets.exceptions import ConnectionClosed

from phantomtouch_client.connection import (
    DEFAULT_WS_URL,
    Backoff,
    PendingReplies,
    SessionState,
    error_from_message,
    open_connection,
    ping_interval_s,
)
from phantomtouch_client.contact import Contact, ContactHelpers, pace_frames
from phantomtouch_client.errors import ApiError, ClientError, ConnectionLost, ReplyTimeout
from phantomtouch_client.models import (
    Job,
    JobId,
    PatternArg,
    Released,
    State,
    Welcome,
    contact_message,
    touch_request,
)

log = logging.getLogger("phantomtouch_client")


class AsyncSession:
    """A WebSocket session with the service.

    >>> async with AsyncSession("ws://127.0.0.1:8000/ws") as ws:      # doctest: +SKIP
    ...     finger = ws.contact("index")
    ...     await finger.down(1.9, 2.0)
    ...     for y in range(2, 13):
    ...         finger.move(1.9, y)          # sent at most once per frame, newest wins
    ...         await asyncio.sleep(1 / 90)
    ...     await finger.up()

    Parameters
    ----------
    url : str
        The service's ``/ws`` address.
    token : str, optional
        The service token (required when the service listens off loopback).
    client_name : str
        Sent in ``hello``; the server shows it in its logs and state.
    wearer : str, optional
        A stored wearer profile the first ``hello`` names: the armband's output stage is
        fitted to it (its band ``wearer_band``, ``sine_100hz`` by default) for every
        client, until another is chosen; a reconnection does not name it again, so a
        later choice by another client stands. A name not stored fails the connection.
    wearer_band : str
    reconnect : bool
        Reconnect with ``backoff`` when the socket is lost (default); else the session
        closes and later calls raise :class:`ConnectionLost`.
    ping_interval_s : float, optional
        Longest silence before the session sends a ``ping``; default a quarter of the
        ``watchdog_s`` the server announces.
    reply_timeout_s : float
        How long a request waits for its reply, and for a lost connection to come back.
    move_rate_hz : float or None
        Frame rate of the :meth:`contact` helpers: each sends at most one ``move`` per
        frame, the newest. ``None``: no timer; call :meth:`flush` once per frame yourself.
    """

    def __init__(
        self,
        url: str = DEFAULT_WS_URL,
        *,
        token: str | None = None,
        client_name: str = "phantomtouch_client",
        wearer: str | None = None,
        wearer_band: str = "sine_100hz",
        reconnect: bool = True,
        backoff: Backoff | None = None,
        ping_interval_s: float | None = None,
        reply_timeout_s: float = 5.0,
        move_rate_hz: float | None = 90.0,
        on_state: Callable[[State], None] | None = None,
        on_released: Callable[[Released], None] | None = None,
        on_error: Callable[[ApiError], None] | None = None,
        on_connection: Callable[[bool], None] | None = None,
    ) -> None:
        if move_rate_hz is not None and not 0 < move_rate_hz <= 1000:
            raise ValueError(f"move_rate_hz={move_rate_hz!r} must be > 0 and <= 1000, or None")
        self.url = url
        self.token = token
        self.client_name = client_name
        self.wearer = wearer
        self.wearer_band = wearer_band
        self.reconnect = reconnect
        self.backoff = backoff or Backoff()
        self.ping_interval_s = ping_interval_s
        self.reply_timeout_s = reply_timeout_s
        self.move_rate_hz = move_rate_hz
        self.on_state = on_state
        self.on_released = on_released
        self.on_error = on_error
        self.on_connection = on_connection

        self.state = SessionState.IDLE
        self.welcome: Welcome | None = None
        self.last_state: State | None = None
        self.reconnects = 0
        """How many times the session has reconnected."""
        self.rtt_s: float | None = None
        """Round-trip time of the newest ping, s."""

        self._ws: ClientConnection | None = None
        self._connected = asyncio.Event()
        self._replies = PendingReplies()
        self._contacts: dict[str, dict[str, Any]] = {}
        self._helpers = ContactHelpers(self)
        self._contact_lock = asyncio.Lock()
        self._subscribed_hz = 0.0
        self._last_send = 0.0
        self._clock_offset_s: float | None = None
        self._tasks: list[asyncio.Task[None]] = []

    async def __aenter__(self) -> Self:
        await self.connect()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    @property
    def connected(self) -> bool:
        return self.state is SessionState.CONNECTED

    @property
    def active_contacts(self) -> dict[str, tuple[float, float]]:
        """The contacts this session holds down, with their newest positions (cm)."""
        return {c: (m["x_cm"], m["y_cm"]) for c, m in self._contacts.items()}

    def server_time_s(self) -> float | None:
        """The server clock now, estimated from the newest ``pong``; ``None`` before one.

        For ``start_at_s``: ``await ws.play(..., start_at_s=ws.server_time_s() + 0.1)``.
        """
        if self._clock_offset_s is None:
            return None
        return time.monotonic() + self._clock_offset_s

    async def connect(self) -> Welcome:
        """Open the socket and say hello; raises :class:`TransportError` if that fails.

        The first connection is not retried, so a wrong address fails at once.
        """
        if self.state is not SessionState.IDLE:
            raise ClientError(f"expected an idle session, got {self.state.value}")
        welcome = await self._open()
        self._set_connected()
        self._tasks = [
            asyncio.create_task(self._supervise(), name="phantomtouch-receive"),
            asyncio.create_task(self._ping_loop(), name="phantomtouch-ping"),
        ]
        if self.move_rate_hz is not None:
            frames = pace_frames(self.move_rate_hz, self.flush)
            self._tasks.append(asyncio.create_task(frames, name="phantomtouch-frame"))
        await self.ping()
        return welcome

    async def close(self) -> None:
        """Close the socket; the server releases this session's contacts with their ramp."""
        if self.state is SessionState.CLOSED:
            return
        self.state = SessionState.CLOSED
        self._connected.clear()
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks = []
        self._replies.fail_all(ConnectionLost("the session was closed"))
        if self._ws is not None:
            await self._ws.close()
            self._ws = None

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
        ``on_error``). While reconnecting, only remembered for the contact's return."""
        message = contact_message("move", contact, x_cm=x_cm, y_cm=y_cm, intensity=intensity)
        tracked = self._contacts.get(contact)
        if tracked is not None:
            tracked["x_cm"], tracked["y_cm"] = x_cm, y_cm
            if intensity is not None:
                tracked["intensity"] = intensity
        if self.connected:
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
            return await asyncio.wait_for(future, self.reply_timeout_s)
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
            await asyncio.wait_for(self._connected.wait(), self.reply_timeout_s)
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

    async def _open(self) -> Welcome:
        """Connect, send ``hello`` and read the ``welcome``."""
        self._ws, self.welcome = await open_connection(
            self.url,
            token=self.token,
            client_name=self.client_name,
            timeout_s=self.reply_timeout_s,
            wearer=self.wearer,
            wearer_band=self.wearer_band,
        )
        self.wearer = None  # named once: a reconnection leaves the armband's choice be
        self._last_send = time.monotonic()
        return self.welcome

    def _set_connected(self) -> None:
        self.state = SessionState.CONNECTED
        self._connected.set()
        if self.on_connection is not None:
            self.on_connection(True)

    async def _supervise(self) -> None:
        """Receive until the socket is lost, then reconnect (or close) and go on."""
        while True:
            ws = self._ws
            assert ws is not None
            try:
                async for frame in ws:
                    if isinstance(frame, str):
                        self._dispatch(frame)
            except ConnectionClosed:
                pass
            if self.state is SessionState.CLOSED:
                return
            self._connected.clear()
            self._replies.fail_all(ConnectionLost(f"the connection to {self.url} was lost"))
            if self.on_connection is not None:
                self.on_connection(False)
            if not self.reconnect:
                self.state = SessionState.CLOSED
                self._ws = None
                return
            self.state = SessionState.RECONNECTING
            await self._reconnect()

    async def _reconnect(self) -> None:
        attempt = 0
        while True:
            await asyncio.sleep(self.backoff.delay_s(attempt))
            attempt += 1
            try:
                await self._open()
            except ClientError as exc:
                log.info("reconnect attempt %d to %s failed: %s", attempt, self.url, exc)
                continue
            try:
                await self._restore()
            except (ConnectionLost, ConnectionClosed) as exc:
                log.info("connection lost again while restoring: %s", exc)
                continue
            self.reconnects += 1
            return

    async def _restore(self) -> None:
        """After a reconnection: contacts back down at their newest positions, re-subscribe."""
        ws = self._ws
        assert ws is not None
        async with self._contact_lock:
            sent = {c: dict(m) for c, m in self._contacts.items()}
            for message in sent.values():
                await self._send(message)
            if self._subscribed_hz:
                await self._send({"type": "subscribe", "rate_hz": self._subscribed_hz})
            self._set_connected()
            for contact, message in self._contacts.items():
                before = sent.get(contact)
                if before is not None and (before["x_cm"], before["y_cm"]) != (
                    message["x_cm"],
                    message["y_cm"],
                ):
                    await self.move(contact, message["x_cm"], message["y_cm"])

    def _dispatch(self, frame: str) -> None:
        try:
            message = json.loads(frame)
        except ValueError:
            log.warning("ignored a frame that is not JSON: %.80r", frame)
            return
        if not isinstance(message, dict):
            log.warning("ignored a frame that is not an object: %.80r", frame)
            return
        if self._replies.settle(message):
            return
        kind = message.get("type")
        if kind == "state":
            self.last_state = State.model_validate(message)
            if self.on_state is not None:
                self.on_state(self.last_state)
        elif kind == "released":
            released = Released.model_validate(message)
            for contact in released.contacts:
                self._contacts.pop(contact, None)
            self._helpers.released(released.contacts)
            if self.on_released is not None:
                self.on_released(released)
        elif kind == "error":
            error = error_from_message(message)
            if self.on_error is not None:
                self.on_error(error)
            else:
                log.warning("server error: %s", error)
        elif kind not in ("pong", "ok", "welcome"):
            log.debug("ignored a message of type %r", kind)

    async def _ping_loop(self) -> None:
        """Send a ``ping`` whenever nothing was sent for ``ping_interval_s``."""
        while True:
            interval = ping_interval_s(self.ping_interval_s, self.welcome)
            idle = time.monotonic() - self._last_send
            if idle < interval:
                await asyncio.sleep(interval - idle)
                continue
            if not self.connected:
                await self._connected.wait()
                continue
            try:
                await self.ping()
            except ReplyTimeout:
                log.warning("no pong within %s s: dropping the connection", self.reply_timeout_s)
                if self._ws is not None:
                    await self._ws.close()
            except ClientError as exc:
                log.debug("ping failed: %s", exc)


__all__ = ["AsyncSession"]
