"""A contact streamed at frame rate: ``move`` at most once per frame, the newest wins.

A hand tracker reports a fingertip more often than is useful (or in bursts); the server
only ever renders the newest position of a contact. :class:`Contact` keeps the newest
position given to :meth:`Contact.move` and its session sends it once per frame, so a burst
of updates costs one message and nothing queues up behind a slow network.
:class:`ContactHelpers` keeps a session's helpers and sends their newest moves, and
:func:`pace_frames` runs that once per frame.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Mapping
from typing import TYPE_CHECKING, Any

from phantomtouch_client.errors import ClientError

if TYPE_CHECKING:
    from phantomtouch_client.session import AsyncSession

log = logging.getLogger("phantomtouch_client")


class Contact:
    """One contact (a fingertip) of a session; make it with ``session.contact(name)``."""

    def __init__(self, session: AsyncSession, name: str) -> None:
        self.session = session
        self.name = name
        self.active = False
        """True between :meth:`down` and :meth:`up` (or the server's release)."""
        self._pending: tuple[float, float, float | None] | None = None

    async def down(
        self,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        carrier: Mapping[str, Any] | None = None,
        law: str | None = None,
        normal_velocity_m_s: float | None = None,
    ) -> None:
        """Touch down at (``x_cm``, ``y_cm``), confirmed by the server."""
        self._pending = None
        await self.session.down(
            self.name,
            x_cm,
            y_cm,
            intensity=intensity,
            carrier=carrier,
            law=law,
            normal_velocity_m_s=normal_velocity_m_s,
        )
        self.active = True

    def move(self, x_cm: float, y_cm: float, *, intensity: float | None = None) -> None:
        """The newest position; sent with the next frame. Never blocks, never queues.

        Ignored while the contact is not down (before :meth:`down`, after :meth:`up`, or
        after the server released it).
        """
        if self.active:
            self._pending = (x_cm, y_cm, intensity)

    async def up(self, *, normal_velocity_m_s: float | None = None) -> None:
        """Lift off where the newest :meth:`move` put the contact (a pending move is sent
        first), then fade out with the release ramp. Nothing is sent for a contact that
        is not down (the server released it, or it was lifted already)."""
        pending = self._take_pending()
        if not self.active:
            return  # never down, already lifted, or released by the server
        self.active = False
        if pending is not None:
            x_cm, y_cm, intensity = pending
            # over /ws, so that it reaches the service before the up that follows it
            await self.session._move(self.name, x_cm, y_cm, intensity=intensity, lane=False)
        await self.session.up(self.name, normal_velocity_m_s=normal_velocity_m_s)

    def _take_pending(self) -> tuple[float, float, float | None] | None:
        pending, self._pending = self._pending, None
        return pending

    def _released(self) -> None:
        self._pending = None
        self.active = False


class ContactHelpers:
    """The :class:`Contact` helpers of one session, by name."""

    def __init__(self, session: AsyncSession) -> None:
        self._session = session
        self._helpers: dict[str, Contact] = {}

    def get(self, name: str) -> Contact:
        """The helper of contact ``name`` (made on first use)."""
        helper = self._helpers.get(name)
        if helper is None:
            helper = self._helpers[name] = Contact(self._session, name)
        return helper

    async def flush(self) -> None:
        """Send the newest pending ``move`` of every helper (one frame)."""
        for helper in self._helpers.values():
            pending = helper._take_pending()
            if pending is not None:
                x_cm, y_cm, intensity = pending
                await self._session.move(helper.name, x_cm, y_cm, intensity=intensity)

    def released(self, names: list[str]) -> None:
        """The server released these contacts: their helpers are up and forget moves."""
        for name in names:
            helper = self._helpers.get(name)
            if helper is not None:
                helper._released()


async def pace_frames(rate_hz: float, flush: Callable[[], Awaitable[None]]) -> None:
    """Call ``flush`` once per frame at ``rate_hz``, for ever (a late frame is not made up)."""
    period = 1.0 / rate_hz
    loop = asyncio.get_running_loop()
    next_frame = loop.time()
    while True:
        next_frame += period
        now = loop.time()
        if next_frame < now:
            next_frame = now + period
        await asyncio.sleep(next_frame - now)
        try:
            await flush()
        except ClientError as exc:
            log.debug("frame flush failed: %s", exc)
