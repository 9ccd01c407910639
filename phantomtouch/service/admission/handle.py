"""A source's handle: everything an input does for one source goes through it.

An input opens one :class:`Handle` per source
(:meth:`~phantomtouch.service.admission.Admission.open`) and translates its protocol into
these calls; it keeps no list of held contacts, no timer, no rate or size check of its own.
The engine's front stays the one record of what is held (``docs/owners.md``).

A typical adapter::

    handle = admission.open("ws", connection_id, principal=principal, on_yield=close_it)
    verdict = handle.receive(len(frame))          # size, rate; renews the owner
    if verdict.admitted:
        handle.down("c1", 1.0, 2.0, arrival=verdict.arrival)
        await handle.play(request, arrival=verdict.arrival)
    ...
    handle.close()                                 # contacts released, touches stopped
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from phantomtouch.errors import ParameterError, ProtocolError
from phantomtouch.service.admission.named import NamedPlays
from phantomtouch.service.admission.principals import DETACHED, owner_id
from phantomtouch.service.admission.rate import Arrival, monotonic
from phantomtouch.service.admission.slots import Opening, Slot
from phantomtouch.service.errors import QuotaError
from phantomtouch.service.scheduling import (
    DETACHED_NAMES,
    Account,
    schedule_held,
    schedule_touch,
)
from phantomtouch.service.scores import ScoreJobs, schedule_score

if TYPE_CHECKING:
    from phantomtouch.clips.tact_score import Score
    from phantomtouch.engine import EngineFront
    from phantomtouch.engine.owners import ReleasedListener
    from phantomtouch.schema.pattern import Carrier
    from phantomtouch.service.models import AnyTouch, JobAccepted
    from phantomtouch.service.store import PatternStore
    from phantomtouch.service.ws_messages import Down

SCOPE_KEY = "phantomtouch.handle"
"""Where a WebSocket session leaves its connection's :class:`Handle` in the ASGI scope, so
that the protocol counts the connection's ping frames in the same rate
(:mod:`phantomtouch.server.wire`)."""


class Handle(Slot):
    """One source of one input, as the admission holds it (made by
    :meth:`~phantomtouch.service.admission.Admission.open`, never directly).

    Every method runs in the host, on the source's own thread or event loop task (one
    call at a time per handle), unless its docstring says otherwise; none waits for the
    audio.

    Attributes
    ----------
    owner : str
        The engine owner of what the source holds: ``PRINCIPAL/SOURCE``.
    detached_owner : str
        The owner of the source's detached touches: its principal's (they outlive it).
    named : NamedPlays
        What the source plays under names its client gave (:mod:`.named`: a view onto the
        engine's tables, for a protocol that lists or stops its plays by name); emptied
        when it closes.

    The others (``kind``, ``source``, ``principal``, ``policy``, ``local``) are a
    :class:`~phantomtouch.service.admission.slots.Slot`'s.
    """

    def __init__(self, engine: EngineFront, store: PatternStore | None, opening: Opening) -> None:
        super().__init__(opening)
        self.engine = engine
        self.store = store
        self.detached_owner = owner_id(opening.principal, DETACHED)
        self.named = NamedPlays(self)
        self._unsubscribe: list[Callable[[], None]] = []

    # -- messages -----------------------------------------------------------------------

    def arrival(self) -> Arrival:
        """An :class:`Arrival` for now, for work the source asked for that did not come as a
        message through :meth:`receive` (an HTTP request). Any thread."""
        return Arrival(self.engine.stop_count, monotonic(None))

    @property
    def stop_count(self) -> int:
        """The engine's stop count: what a message's
        :class:`~phantomtouch.service.admission.Arrival` is stamped with (a stop since
        voids what it asked for). Any thread."""
        return self.engine.stop_count

    def renew(self, now_s: float | None = None) -> None:
        """Push the deadline of the owner's contacts on: a message of this owner was heard
        (:meth:`~phantomtouch.service.admission.slots.Slot.receive` does it for every
        admitted message; an input calls it itself only for a message that does not pass
        it, such as a transport ping frame)."""
        now_s = monotonic(now_s)
        super().renew(now_s)
        self.engine.renew_owner(self.owner, now_s)

    def holds_anything(self) -> bool:
        """Whether the source holds a contact or a touch (the front's tables). Any thread."""
        return bool(self.engine.contacts_of(self.owner)) or bool(self.engine.live_jobs(self.owner))

    def check_work(self, count: int, *, field: str) -> None:
        """Refuse a message asking for ``count`` units of work (voices, submits, messages of
        a datagram) over the row's ``max_work``, before any of it is done.

        Raises
        ------
        ParameterError
            Naming ``field``, ``count`` and the limit.
        """
        if count > self.policy.max_work:
            raise ParameterError(
                f"{field}: {count} in one message; at most {self.policy.max_work} "
                f"({self.kind} max_work)"
            )

    # -- contacts -----------------------------------------------------------------------

    def down(
        self,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        carrier: Carrier | None = None,
        law: str = "power",
        normal_velocity_m_s: float | None = None,
    ) -> None:
        """Put ``contact`` of this source down at (x_cm, y_cm), with the row's deadline
        (arguments and ranges: :meth:`~phantomtouch.engine.EngineFront.contact_down`).

        Raises
        ------
        ProtocolError
            The contact is already down ("expected move or up, got down").
        QuotaError
            The source holds ``contacts_per_owner`` contacts (field ``contact``).
        ParameterError, EngineBusyError, DeviceError
            From the engine's front.
        """
        held = self.engine.contacts_of(self.owner)
        if contact in held:
            raise ProtocolError(
                f"contact={contact!r} is already down: expected move or up, got down"
            )
        limit = self.policy.contacts_per_owner
        if len(held) >= limit:
            raise QuotaError(
                f"contact={contact!r}: quota {self.policy.contacts_setting}={limit} "
                f"(contacts one {self.kind} source holds down at once) is used up; send up "
                "for one first",
                field="contact",
                value=contact,
            )
        deadline_s = self.policy.deadline_s
        self.engine.contact_down(
            self.owner,
            contact,
            x_cm,
            y_cm,
            intensity=intensity,
            carrier=carrier,
            law=law,
            normal_velocity_m_s=normal_velocity_m_s,
            deadline_s=deadline_s if math.isfinite(deadline_s) else None,
        )

    def down_as(self, message: Down) -> None:
        """:meth:`down` as a protocol's ``down`` message says (its contact, position in cm,
        intensity, carrier, law and normal velocity); the WebSocket's and fleet's."""
        self.down(
            message.contact,
            message.x_cm,
            message.y_cm,
            intensity=message.intensity,
            carrier=message.carrier,
            law=message.law,
            normal_velocity_m_s=message.normal_velocity_m_s,
        )

    def prepare_carrier(self, carrier: Carrier | None) -> None:
        """Build what ``carrier`` needs ahead, so that a later :meth:`down` with it does not
        wait (host, meant for a worker thread)."""
        self.engine.prepare_carrier(carrier)

    def move(
        self, contact: str, x_cm: float, y_cm: float, *, intensity: float | None = None
    ) -> None:
        """The newest position of ``contact`` (latest wins, nothing queues).

        Raises
        ------
        ProtocolError
            The contact is not down ("expected down, got move"): released by ``up``, its
            deadline, a stop or a quota.
        ParameterError
            A value is out of range.
        """
        if not self.engine.holds(self.owner, contact):
            raise ProtocolError(
                f"contact={contact!r} is not down: expected down, got move "
                "(a contact is released by up, the watchdog or stop)"
            )
        self.engine.contact_move(self.owner, contact, x_cm, y_cm, intensity=intensity)

    def up(self, contact: str, *, normal_velocity_m_s: float | None = None) -> bool:
        """Lift ``contact`` (it fades out over the release); returns whether it was down
        (an ``up`` of a contact that is not down does nothing).

        Raises
        ------
        ParameterError
            ``normal_velocity_m_s`` out of range.
        """
        if not self.engine.holds(self.owner, contact):
            return False
        self.engine.contact_up(self.owner, contact, normal_velocity_m_s=normal_velocity_m_s)
        return True

    def holds(self, contact: str) -> bool:
        """Whether ``contact`` of this source is down (the front's owner table). Any thread."""
        return self.engine.holds(self.owner, contact)

    def contacts(self) -> list[str]:
        """The contacts this source holds down, oldest first. Any thread."""
        return self.engine.contacts_of(self.owner)

    def release(self, reason: str = "released") -> None:
        """Release every contact of this source (release ramp; published ``released`` with
        ``reason``); its touches play on. Any thread."""
        self.engine.release_owner(self.owner, reason)

    def on_released(self, listener: ReleasedListener) -> None:
        """Call ``listener(owner, contacts, reason)`` whenever the front lets go of contacts
        of this source without an ``up`` (in the releasing thread: it must return at once,
        :data:`~phantomtouch.engine.owners.ReleasedListener`); until :meth:`close`."""
        self._unsubscribe.append(self.engine.subscribe_released(listener, self.owner))

    # -- touches ------------------------------------------------------------------------

    async def play(
        self, request: AnyTouch, *, arrival: Arrival, detached: bool = False
    ) -> JobAccepted:
        """Resolve, plan and schedule a touch request as a job of this source (host, the
        event loop); the one touch path
        (:func:`~phantomtouch.service.scheduling.schedule_touch`): the quota is checked
        before planning, and a stop after ``arrival`` voids it. A touch whose plan the
        engine holds rendered whole and that reads no library (a repeated tap) is
        scheduled on the event loop at once
        (:func:`~phantomtouch.service.scheduling.schedule_held`); any other is resolved
        and planned in a worker thread.

        Parameters
        ----------
        request : AnyTouch
        arrival : Arrival
            The arrival of the message that asked for it (:meth:`receive`,
            :meth:`arrival`).
        detached : bool
            True: the touch is the principal's (:attr:`detached_owner`), under the row's
            ``detached_quota``, and outlives this source.

        Raises
        ------
        QuotaError, NotFoundError, MissingReferenceError, ParameterError, EngineBusyError
        """
        held = schedule_held(
            self.engine, request, account=self._account(detached), stop_count=arrival.stop_count
        )
        if held is not None:
            return held
        return await asyncio.to_thread(self.play_now, request, arrival=arrival, detached=detached)

    def play_now(
        self, request: AnyTouch, *, arrival: Arrival, detached: bool = False
    ) -> JobAccepted:
        """:meth:`play` in the caller's thread (host, a worker thread, never the event
        loop: it plans)."""
        return schedule_touch(
            self.engine,
            self.store,
            request,
            account=self._account(detached),
            stop_count=arrival.stop_count,
        )

    def _account(self, detached: bool) -> Account:
        """What a touch of this source goes on: the source's own owner and the row's
        quota, or (``detached``) the principal's :attr:`detached_owner` and the row's
        ``detached_quota``."""
        if detached:
            return Account(self.detached_owner, self.policy.detached_quota, DETACHED_NAMES)
        return Account(self.owner, self.policy.quota)

    def play_score(
        self,
        played: Score,
        *,
        arrival: Arrival,
        start_frame: int | None = None,
        skip_s: float = 0.0,
        partial: bool = False,
    ) -> ScoreJobs:
        """Schedule every voice of ``played`` as a job of this source under its quota (host,
        a worker thread: it plans); :func:`~phantomtouch.service.scores.schedule_score`
        with the row's quota and ``arrival``'s stop count: a stop after the message voids
        every voice, also one that comes while they are planned.

        Raises
        ------
        ParameterError
            More voices than the row's ``max_work`` (field ``voices``), or a voice more than
            an hour ahead.
        QuotaRefused, EngineBusyError
            ``partial`` is False and a voice was refused (the ones scheduled are stopped).
        """
        self.check_work(len(played.voices), field="voices")
        return schedule_score(
            self.engine,
            played,
            owner=self.owner,
            quota=self.policy.quota,
            stop_count=arrival.stop_count,
            start_frame=start_frame,
            skip_s=skip_s,
            partial=partial,
        )

    def stop_touches(self, reason: str = "closed") -> int:
        """Stop every touch of this source scheduled or playing (release ramp); returns how
        many (a named play of them is over at the next look of :attr:`named`). Any
        thread."""
        return self.engine.stop_owner(self.owner, reason)

    # -- the slot -----------------------------------------------------------------------

    def let_go(self, reason: str) -> None:
        """What :meth:`~phantomtouch.service.admission.slots.Slot.close` lets go of: the
        source's contacts (``released`` with ``reason``, heard by its :meth:`on_released`
        listeners) and its touches but the detached ones; its named plays are forgotten.
        Any thread."""
        self.named.clear()
        self.engine.release_owner(self.owner, reason)
        self.engine.stop_owner(self.owner, reason)
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe.clear()
