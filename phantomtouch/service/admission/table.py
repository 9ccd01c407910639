"""The admission: the sources of every input, their slots, and who yields when full."""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from phantomtouch.engine.shares import yielding
from phantomtouch.errors import ParameterError
from phantomtouch.service.admission.handle import Handle, YieldCallback
from phantomtouch.service.admission.policy import KINDS, InputPolicy, Kind
from phantomtouch.service.admission.principals import check_principal
from phantomtouch.service.admission.rate import Arrival, Meter, check_size, monotonic
from phantomtouch.service.errors import SourcesFullError
from phantomtouch.service.flood import FloodGuard


@dataclass
class _Group:
    """The open sources of one principal on one input, and their shared bucket."""

    rate: FloodGuard
    sources: dict[str, Handle] = field(default_factory=dict)


KindListener = Callable[[Handle, tuple[str, ...], str], None]
"""``listener(handle, contacts, reason)``: the front let go of ``contacts`` of ``handle``'s
source without an ``up`` (:meth:`Admission.on_released`)."""

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
        Where touch requests' stored patterns and clips are read; None: presets and
        inline patterns only (a request naming a stored pattern is not found).
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
        self._owners: dict[str, Handle] = {}
        self._groups: dict[tuple[str, str], _Group] = {}
        """The open sources of each (kind, principal), with the principal's shared bucket;
        a group goes with its last source."""
        self._counts: dict[str, int] = {}
        """Open sources by kind."""
        self._serial = itertools.count(1)

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
        local: bool = False,
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
        local : bool
            The source is on this machine (a loopback peer,
            :func:`~phantomtouch.service.connections.is_loopback_address`): under a row
            with ``local_never_yields`` it never yields and is never refused.
        now_s : float or None
            ``time.monotonic()`` now (None: read it).

        Raises
        ------
        SourcesFullError
            Every slot is taken by sources that never yield (local ones under
            ``local_never_yields``) or none yields to this one (503; a WebSocket closes
            1013).
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
            victim = self._victim(policy, principal, local)
            if victim is not None:
                self._forget(victim)
            group = self._groups.get((kind, principal))
            if group is None:
                rate = policy.messages_per_s * policy.principal_factor
                group = self._groups[(kind, principal)] = _Group(FloodGuard(rate))
            handle = Handle(
                self.engine,
                self.store,
                policy,
                source=source,
                principal=principal,
                meter=Meter(
                    kind, policy.max_message_bytes, FloodGuard(policy.messages_per_s), group.rate
                ),
                on_yield=on_yield,
                on_close=self._closed,
                local=local,
            )
            handle.last_heard_s = now_s
            self._open[key] = handle
            self._owners[handle.owner] = handle
            group.sources[source] = handle
            self._counts[kind] = self._counts.get(kind, 0) + 1
        if victim is not None:
            victim.yield_slot(
                f"{kind} slots full (max_sources={policy.max_sources}, "
                f"{policy.max_sources_per_principal} per host): made room for a newcomer"
            )
        return handle

    def new_source(self) -> str:
        """A source name never given before by this admission, for an input whose sources
        have no name of their own (a WebSocket connection). Any thread."""
        return f"c{next(self._serial)}"

    def arrival(self) -> Arrival:
        """An :class:`~phantomtouch.service.admission.Arrival` for now: for a message an
        input reads before it knows its source (a fleet touch names its client inside).
        Any thread."""
        return Arrival(self.engine.stop_count, monotonic(None))

    def check_size(self, kind: Kind, size_bytes: int) -> None:
        """Refuse a message of ``kind`` of ``size_bytes`` bytes over the row's
        ``max_message_bytes`` before it is read (an input whose messages name their source
        inside: a fleet contact message). Any thread.

        Raises
        ------
        TooLargeError
        """
        check_size(kind, self.policy(kind).max_message_bytes, size_bytes)

    def on_released(self, kind: Kind, listener: KindListener) -> Callable[[], None]:
        """Call ``listener(handle, contacts, reason)`` whenever the front lets go of
        contacts of an open source of ``kind`` without an ``up``, in the releasing thread
        (it must return at once and must not call the front back); returns the function
        that unsubscribes it. Any thread."""

        def released(owner: str, contacts: tuple[str, ...], reason: str) -> None:
            handle = self._owners.get(owner)
            if handle is not None and handle.kind == kind:
                listener(handle, contacts, reason)

        return self.engine.subscribe_released(released)

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
                self._forget(handle)

    def _forget(self, handle: Handle) -> None:
        """Take ``handle`` out of the tables (lock held)."""
        del self._open[(handle.kind, handle.source)]
        self._owners.pop(handle.owner, None)
        self._counts[handle.kind] -= 1
        group = self._groups[(handle.kind, handle.principal)]
        del group.sources[handle.source]
        if not group.sources:
            del self._groups[(handle.kind, handle.principal)]

    def _victim(self, policy: InputPolicy, principal: str, local: bool) -> Handle | None:
        """The source that yields its slot to a newcomer of ``principal`` (lock held), or
        None when there is room (or the newcomer is local under ``local_never_yields``).
        When the input is
        full some source yields if any may: the fair-share rule over the principals' slots
        (:func:`~phantomtouch.engine.shares.yielding`) picks the principals; when none of
        another principal does, one of the newcomer's own principal does (its sources pass
        the slots round), so no crowd, idle or not, locks a newcomer out; only sources that
        never yield can fill it. Among them a source holding nothing goes first, then the
        one silent longest; the cost is that of one principal's sources, not the input's."""
        kind = policy.kind
        if local and policy.local_never_yields:
            return None
        group = self._groups.get((kind, principal))
        mine = 0 if group is None else len(group.sources)
        if mine >= policy.max_sources_per_principal:
            principals = [principal]
        elif self._counts.get(kind, 0) >= policy.max_sources:
            held = {p: len(g.sources) for (k, p), g in self._groups.items() if k == kind}
            principals = yielding(held, principal) or [principal]
        else:
            return None
        never = policy.local_never_yields
        candidates = [
            h
            for p in principals
            if (g := self._groups.get((kind, p))) is not None
            for h in g.sources.values()
            if not (never and h.local)
        ]
        if not candidates:
            raise SourcesFullError(
                f"{kind}: {self._counts.get(kind, 0)} sources are open (max_sources="
                f"{policy.max_sources}, {policy.max_sources_per_principal} per host or token) "
                "and none may yield to this one; retry later",
                field="connection",
                value=self._counts.get(kind, 0),
            )
        candidates.sort(key=lambda h: h.last_heard_s)
        return next((h for h in candidates if not self._holds_anything(h)), candidates[0])

    def _holds_anything(self, handle: Handle) -> bool:
        return bool(self.engine.contacts_of(handle.owner)) or bool(
            self.engine.live_jobs(handle.owner)
        )
