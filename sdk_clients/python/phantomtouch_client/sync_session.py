"""The blocking WebSocket session: :class:`AsyncSession` run on a background event loop.

The session's receive, ping, reconnect and frame tasks need to run while the caller's
thread does other work (or sleeps between trials of an experiment), so :class:`Session`
owns one event loop in a daemon thread and every method hands its call to that loop and
waits for the answer. Callbacks (``on_state`` ...) run in that thread.
"""

from __future__ import annotations

import asyncio
import functools
import threading
from collections.abc import Coroutine, Mapping
from types import TracebackType
from typing import Any, Self, TypeVar

from phantomtouch_client.connection import DEFAULT_WS_URL, SessionState
from phantomtouch_client.contact import Contact
from phantomtouch_client.lane import ContactLane
from phantomtouch_client.models import Job, JobId, PatternArg, State, Welcome
from phantomtouch_client.session import AsyncSession

T = TypeVar("T")


class Session:
    """A blocking WebSocket session; the same options and methods as :class:`AsyncSession`.

    >>> with Session("ws://127.0.0.1:8000/ws") as ws:             # doctest: +SKIP
    ...     finger = ws.contact("index")
    ...     finger.down(1.9, 2.0)
    ...     for y in range(2, 13):
    ...         finger.move(1.9, y)          # returns at once; sent with the next frame
    ...         time.sleep(1 / 90)
    ...     finger.up()
    """

    def __init__(self, url: str = DEFAULT_WS_URL, **options: Any) -> None:
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(
            target=self._loop.run_forever, name="phantomtouch-session", daemon=True
        )
        self._thread.start()
        self._async = self._call(self._create(url, options))

    @staticmethod
    async def _create(url: str, options: dict[str, Any]) -> AsyncSession:
        return AsyncSession(url, **options)

    def _call(self, coro: Coroutine[Any, Any, T]) -> T:
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result()

    def __enter__(self) -> Self:
        try:
            self.connect()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def state(self) -> SessionState:
        return self._async.state

    @property
    def connected(self) -> bool:
        return self._async.connected

    @property
    def welcome(self) -> Welcome | None:
        return self._async.welcome

    @property
    def last_state(self) -> State | None:
        return self._async.last_state

    @property
    def lane(self) -> ContactLane | None:
        """The contact lane the moves go over, if any (see :class:`AsyncSession`)."""
        return self._async.lane

    @property
    def reconnects(self) -> int:
        return self._async.reconnects

    @property
    def rtt_s(self) -> float | None:
        return self._async.rtt_s

    @property
    def active_contacts(self) -> dict[str, tuple[float, float]]:
        return self._call(self._snapshot_contacts())

    async def _snapshot_contacts(self) -> dict[str, tuple[float, float]]:
        return self._async.active_contacts

    def server_time_s(self) -> float | None:
        """The server clock now, estimated from the newest ``pong``."""
        return self._async.server_time_s()

    def connect(self) -> Welcome:
        """Open the socket and say hello; see :meth:`AsyncSession.connect`."""
        return self._call(self._async.connect())

    def close(self) -> None:
        """Close the socket and stop the session's thread."""
        if self._loop.is_closed():
            return
        try:
            self._call(self._async.close())
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5)
            self._loop.close()

    def contact(self, name: str) -> SyncContact:
        """The frame-rate helper of contact ``name``; see :class:`Contact`."""
        return SyncContact(self, self._async.contact(name))

    def flush(self) -> None:
        self._call(self._async.flush())

    def down(
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
        self._call(
            self._async.down(
                contact,
                x_cm,
                y_cm,
                intensity=intensity,
                carrier=carrier,
                law=law,
                normal_velocity_m_s=normal_velocity_m_s,
            )
        )

    def move(
        self, contact: str, x_cm: float, y_cm: float, *, intensity: float | None = None
    ) -> None:
        self._call(self._async.move(contact, x_cm, y_cm, intensity=intensity))

    def up(self, contact: str, *, normal_velocity_m_s: float | None = None) -> None:
        self._call(self._async.up(contact, normal_velocity_m_s=normal_velocity_m_s))

    def play(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
        start_in_ms: float | None = None,
        start_at_s: float | None = None,
    ) -> Job:
        return self._call(
            self._async.play(
                pattern,
                preset=preset,
                stored=stored,
                overrides=overrides,
                start_in_ms=start_in_ms,
                start_at_s=start_at_s,
            )
        )

    def stop(self, job_id: JobId | None = None) -> Any:
        return self._call(self._async.stop(job_id))

    def subscribe(self, rate_hz: float) -> None:
        self._call(self._async.subscribe(rate_hz))

    def ping(self) -> float:
        return self._call(self._async.ping())

    def request(self, message: Mapping[str, Any]) -> Any:
        return self._call(self._async.request(message))


class SyncContact:
    """The blocking face of a :class:`Contact`: ``move`` returns at once, from any thread."""

    def __init__(self, session: Session, contact: Contact) -> None:
        self._session = session
        self._contact = contact
        self.name = contact.name

    @property
    def active(self) -> bool:
        return self._contact.active

    def down(
        self,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        carrier: Mapping[str, Any] | None = None,
        law: str | None = None,
        normal_velocity_m_s: float | None = None,
    ) -> None:
        self._session._call(
            self._contact.down(
                x_cm,
                y_cm,
                intensity=intensity,
                carrier=carrier,
                law=law,
                normal_velocity_m_s=normal_velocity_m_s,
            )
        )

    def move(self, x_cm: float, y_cm: float, *, intensity: float | None = None) -> None:
        self._session._loop.call_soon_threadsafe(
            functools.partial(self._contact.move, x_cm, y_cm, intensity=intensity)
        )

    def up(self, *, normal_velocity_m_s: float | None = None) -> None:
        self._session._call(self._contact.up(normal_velocity_m_s=normal_velocity_m_s))


__all__ = ["Session", "SyncContact"]
