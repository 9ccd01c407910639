"""A contact streamed at frame rate: ``move`` at most once per frame, the newest wins.

A hand tracker reports a fingertip more often than is useful (or in bursts); the server
only ever renders the newest position of a contact. :class:`Contact` keeps the newest
position given to :meth:`Contact.move` and its session sends it once per frame, so a burst
of updates costs one message and nothing queues up behind a slow network.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from phantomtouch_client.session import AsyncSession


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
            await self.session.move(self.name, x_cm, y_cm, intensity=intensity)
        await self.session.up(self.name, normal_velocity_m_s=normal_velocity_m_s)

    def _take_pending(self) -> tuple[float, float, float | None] | None:
        pending, self._pending = self._pending, None
        return pending

    def _released(self) -> None:
        self._pending = None
        self.active = False
