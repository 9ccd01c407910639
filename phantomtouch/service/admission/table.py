"""The admission: the sources of every input, their slots, and who yields when full."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import TYPE_CHECKING

from phantomtouch.engine.shares import yielding
from phantomtouch.errors import ParameterError
from phantomtouch.service.admission.handle import Handle, YieldCallback
from phantomtouch.service.admission.policy import KINDS, InputPolicy, Kind
from phantomtouch.service.admission.principals import check_principal, owner_id
from phantomtouch.service.admission.rate import Meter, monotonic
from phantomtouch.service.flood import FloodGuard

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront
    from phantomtouch.service.store import PatternStore


class Admission:
    """The one admission of a service: every input opens its sources here and does
    everything through their :class:`~phantomtouch.service.admission.Handle`.

    Host, any thread: every method takes the admission's lock for its own bookkeeping
    and calls a yielded source's ``on_yield`` outside it.

    Parameters
    ----------
    engine : EngineFront
        The engine's front, whose owner and job tables are the one record of what each
        source holds.
    policies : mapping of kind to InputPolicy
        The policy table (:func:`~phantomtouch.service.admission.policy_table`); a kind
        missing from it cannot be opened.
    store : PatternStore or None
        Where touch requests' stored patterns and clips are read; None: an input that
        plays plans and scores only (the OSC bridge on its own).
    """

    def __init__(
        self,
        engine: EngineFront,
        policies: Mapping[Kind, InputPolicy],
        *,
        store: PatternStore | None = None,
    ) -> None:
        self.engine = engine
        self.store = store
        self._policies: dict[Kind, InputPolicy] = dict(policies)
        self._lock = threading.Lock()
        self._open: dict[tuple[str, str], Handle] = {}
        self._shared: dict[tuple[str, str], FloodGuard] = {}

    # -- the table ----------------------------------------------------------------------

    def policy(self, kind: Kind) -> InputPolicy:
        """The row of ``kind``.

        Raises
        ------
        ParameterError
            No such row.
        """
        try:
            return self._policies[kind]
        except KeyError:
            raise ParameterError(
                f"kind={kind!r} is not an input of this admission; one of "
                f"{sorted(self._policies)} (all kinds: {list(KINDS)})"
            ) from None

    def set_policy(self, policy: InputPolicy) -> None:
        """Replace the row of ``policy.kind`` (an input whose own configuration sets part
        of it, such as the OSC map's ``watchdog_s``); sources opened afterwards follow it."""
        with self._lock:
            self._policies[policy.kind] = policy

    @property
    def policies(self) -> dict[Kind, InputPolicy]:
        """The policy table, by kind (a copy)."""
        return dict(self._policies)

    # -- sources ------------------------------------------------------------------------

    def open(
        self,
        kind: Kind,
        source: str,
        *,
        principal: str,
        on_yield: YieldCallback | None = None,
        now_s: float | None = None,
    ) -> Handle:
        """The handle of ``source`` of input ``kind``: the one already open, or a new one
        in a free connection slot.

        When the input's ``max_sources`` slots are full, or ``principal`` holds its
        ``max_sources_per_principal``, a source yields its slot (:data:`~phantomtouch.
        service.admission.policy.YIELDS`): the fair-share rule
        (:func:`~phantomtouch.engine.shares.yielding`) picks the principals that yield,
        first among principals, then among the newcomer's own principal's sources; among
        those, a source holding nothing (no contact, no touch) yields first, then the one
        silent longest. The yielded source is closed (contacts released ``quota``,
        touches stopped) and its ``on_yield(reason)`` called.

        Parameters
        ----------
        kind : str
            A row of the policy table.
        source : str, non-empty
            The source as the input tells it apart (a connection id, ``HOST:PORT``, a fleet
            owner id); unique within ``kind``.
        principal : str
            Who the source is (:func:`~phantomtouch.service.admission.principal_for`).
        on_yield : callable or None
            ``on_yield(reason)``: end the source's transport when the admission takes its
            slot (:data:`~phantomtouch.service.admission.handle.YieldCallback`).
        now_s : float or None
            ``time.monotonic()`` now (None: read it).

        Raises
        ------
        ParameterError
            Unknown ``kind``, empty ``source``, or a malformed ``principal``.
        """
        policy = self.policy(kind)
        check_principal(principal)
        if not isinstance(source, str) or not source:
            raise ParameterError(f"source={source!r} must be a non-empty string")
        now_s = monotonic(now_s)
        key = (kind, source)
        with self._lock:
            handle = self._open.get(key)
            if handle is not None and not handle.closed:
                return handle
            victim = self._victim(policy, principal, owner_id(principal, source))
            if victim is not None:
                self._open.pop((victim.kind, victim.source), None)
            shared = self._shared.get((kind, principal))
            if shared is None:
                rate = policy.messages_per_s * policy.principal_factor
                shared = self._shared[(kind, principal)] = FloodGuard(rate)
            handle = Handle(
                self.engine,
                self.store,
                policy,
                source=source,
                principal=principal,
                meter=Meter(
                    kind, policy.max_message_bytes, FloodGuard(policy.messages_per_s), shared
                ),
                on_yield=on_yield,
                on_close=self._closed,
            )
            handle.last_heard_s = now_s
            self._open[key] = handle
        if victim is not None:
            victim.yield_slot(
                f"{kind}: every connection slot is taken (max_sources={policy.max_sources}, "
                f"{policy.max_sources_per_principal} per host or token): this one, "
                "silent longest, made room for a newcomer"
            )
        return handle

    def handles(self, kind: Kind) -> list[Handle]:
        """The sources of ``kind`` open now, opened first first. Any thread."""
        with self._lock:
            return [h for (k, _), h in self._open.items() if k == kind]

    def close_all(self, kind: Kind, reason: str = "closed") -> None:
        """Close every source of ``kind`` (the input stops), releasing what they hold."""
        for handle in self.handles(kind):
            handle.close(reason)

    def stop_all(self) -> None:
        """The emergency stop: every touch and contact of every input off at once (never
        queued); whatever a source sent before it is void, also what is still being
        planned (:class:`~phantomtouch.service.admission.Arrival`). Any thread."""
        self.engine.stop_all()

    def _closed(self, handle: Handle) -> None:
        with self._lock:
            if self._open.get((handle.kind, handle.source)) is handle:
                del self._open[(handle.kind, handle.source)]

    def _victim(self, policy: InputPolicy, principal: str, newcomer: str) -> Handle | None:
        """The source that yields its slot to ``newcomer`` (lock held), or None when there
        is room. When the input is full some source always yields: if no other principal
        does, one of the newcomer's own principal does (its sources pass the slots round),
        so no crowd, idle or not, locks a newcomer out."""
        mine = [h for (k, _), h in self._open.items() if k == policy.kind]
        siblings = [h for h in mine if h.principal == principal]
        if len(siblings) >= policy.max_sources_per_principal:
            candidates = siblings
        elif len(mine) >= policy.max_sources:
            givers = set(yielding({h.owner: 1 for h in mine}, newcomer))
            candidates = [h for h in mine if h.owner in givers]
        else:
            return None
        return min(candidates, key=lambda h: (self._holds_anything(h), h.last_heard_s))

    def _holds_anything(self, handle: Handle) -> bool:
        return bool(self.engine.contacts_of(handle.owner)) or bool(
            self.engine.live_jobs(handle.owner)
        )
