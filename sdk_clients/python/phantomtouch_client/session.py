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

The calls a session answers (``down``, ``move``, ``up``, ``play``, ``stop``, ``subscribe``,
``ping``, ``request``) and how they wait for their replies are in
:mod:`phantomtouch_client.session_calls`; this module makes the session and keeps its
connection: it receives, dispatches, pings, reconnects and restores. Callbacks
(``on_state``, ``on_released``, ``on_error``, ``on_connection``) run in the event loop and
must return quickly.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import Callable
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
from phantomtouch_client.contact import ContactHelpers, pace_frames
from phantomtouch_client.errors import ApiError, ClientError, ConnectionLost, ReplyTimeout
from phantomtouch_client.lane import ContactLane
from phantomtouch_client.models import Released, State, Welcome
from phantomtouch_client.session_calls import SessionCalls

log = logging.getLogger("phantomtouch_client")

CANCEL_AGAIN_S = 0.05
"""How long :meth:`AsyncSession.close` waits for one of its tasks to end before it
cancels it again, s."""


class AsyncSession(SessionCalls):
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
    lane : bool
        Send moves over the service's contact lane when its ``welcome`` offers one and its
        host is reachable by UDP (default): a UDP datagram the service takes without
        waiting behind its HTTP work (:mod:`phantomtouch_client.lane`). False: every
        message goes over ``/ws``.
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
        lane: bool = True,
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
        self.use_lane = lane
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
        self.lane: ContactLane | None = None
        """The contact lane of the current connection, if one was offered and reached."""
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
    def active_contacts(self) -> dict[str, tuple[float, float]]:
        """The contacts this session holds down, with their newest positions (cm)."""
        return {c: (m["x_cm"], m["y_cm"]) for c, m in self._contacts.items()}

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
            await _cancel_until_done(task)
        self._tasks = []
        self._replies.fail_all(ConnectionLost("the session was closed"))
        self._close_lane()
        if self._ws is not None:
            await self._ws.close()
            self._ws = None

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
        self._close_lane()
        peer = self._ws.remote_address
        if self.use_lane and self.welcome.lane is not None and peer:
            host = str(peer[0])
            self.lane = await ContactLane.open(self.welcome.lane.model_dump(), host, self._dispatch)
            if self.lane is not None:
                # contacts to restore: their downs go over /ws first, unconfirmed
                self.lane.held = bool(self._contacts)
        return self.welcome

    async def _release_lane(self, lane: ContactLane) -> None:
        """Moves take ``lane`` once a pong shows that the service has read what was sent
        over ``/ws`` before it (the restored downs)."""
        with contextlib.suppress(ClientError):
            await self.ping()
            lane.held = False

    def _close_lane(self) -> None:
        """The lane of the connection that ended is closed with it."""
        if self.lane is not None:
            self.lane.close()
            self.lane = None

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
                self._close_lane()
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
            if self.lane is not None and self.lane.held:
                release = self._release_lane(self.lane)
                self._tasks.append(asyncio.create_task(release, name="phantomtouch-lane"))
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
                    # over /ws, behind the downs just sent and not yet confirmed
                    await self._move(contact, message["x_cm"], message["y_cm"], lane=False)

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


async def _cancel_until_done(task: asyncio.Task[Any]) -> None:
    """Cancel ``task`` again every :data:`CANCEL_AGAIN_S` until it has ended (a library
    it waits in may swallow a cancel that comes as its result does); how it ended is
    dropped."""
    while not task.done():
        task.cancel()
        await asyncio.wait({task}, timeout=CANCEL_AGAIN_S)
    if not task.cancelled():
        with contextlib.suppress(Exception):
            task.result()


__all__ = ["AsyncSession"]
