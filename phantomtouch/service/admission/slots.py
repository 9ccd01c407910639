"""The connection half of the admission: sources in slots, their size and rate, who
yields when the slots are full. It needs no engine, so a process without one (the fleet's
gateway, :mod:`phantomtouch.fleet.gateway_ws`) holds its connections to the same rules
as a service does; the owner half (contacts, touches, deadlines) is the
:class:`~phantomtouch.service.admission.Handle`'s, on the process that holds the engine.

A :class:`Slot` is one source in a slot; :class:`Slots` is the table of them for each
input kind of a policy table. :class:`~phantomtouch.service.admission.Admission` is a
:class:`Slots` whose slots are :class:`~phantomtouch.service.admission.Handle`\\ s.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from phantomtouch.engine.shares import yielding
from phantomtouch.errors import ParameterError
from phantomtouch.service.admission.policy import KINDS, InputPolicy, Kind
from phantomtouch.service.admission.principals import check_principal, owner_id
from phantomtouch.service.admission.rate import Meter, Verdict, check_size, monotonic
from phantomtouch.service.errors import SourcesFullError
from phantomtouch.service.flood import FloodGuard

YieldCallback = Callable[[str], None]
"""``on_yield(reason)``: the admission took the source's slot for a newcomer (or closed
it); the adapter ends the source's transport (a WebSocket closes 1013 with ``reason``).
Called in the thread that opened the newcomer; it must return at once."""


@dataclass(frozen=True)
class Opening:
    """What a source's slot is made from (:meth:`Slots.open` builds it, ``make`` of
    :class:`Slots` turns it into the slot; host, any thread; immutable).

    Attributes
    ----------
    policy : InputPolicy
        The input's row.
    source : str
        The source as the input names it.
    principal : str
        Who the source really is.
    meter : Meter
        The source's size and rate checks, with its principal's shared bucket.
    on_yield : YieldCallback or None
        The adapter's: end the source's transport when its slot is taken.
    on_close : callable
        ``on_close(slot)``: the table forgets the closed slot.
    local : bool
        The source is on this machine.
    """

    policy: InputPolicy
    source: str
    principal: str
    meter: Meter
    on_yield: YieldCallback | None
    on_close: Callable[[Slot], None]
    local: bool = False


class Slot:
    """One source of one input in a slot of :class:`Slots` (made by :meth:`Slots.open`,
    never directly).

    Every method runs in the host, on the source's own thread or event loop task (one
    call at a time per slot), unless its docstring says otherwise.

    Attributes
    ----------
    kind : str
        The input kind (a row of the policy table).
    source : str
        The source as the input names it (a connection id, ``HOST:PORT``, a fleet owner).
    principal : str
        Who the source really is (:func:`~phantomtouch.service.admission.principal_for`).
    owner : str
        The source's name as one of its principal's: ``PRINCIPAL/SOURCE``.
    policy : InputPolicy
        The input's row.
    meter : Meter
        The source's size and rate checks, with its principal's shared bucket.
    local : bool
        The source is on this machine (its row's ``local_never_yields`` applies).
    last_heard_s : float
        ``time.monotonic()`` of the source's last admitted message.
    closed : bool
        The source went (or yielded its slot).
    """

    def __init__(self, opening: Opening) -> None:
        self.policy = opening.policy
        self.kind = opening.policy.kind
        self.source = opening.source
        self.principal = opening.principal
        self.owner = owner_id(opening.principal, opening.source)
        self.meter = opening.meter
        self.local = opening.local
        self.last_heard_s = monotonic(None)
        self.closed = False
        self._on_yield = opening.on_yield
        self._on_close = opening.on_close

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.kind!r}, owner={self.owner!r})"

    @property
    def stop_count(self) -> int:
        """The stop count a message's :class:`~phantomtouch.service.admission.Arrival` is
        stamped with: 0 for a slot with no engine behind it (the process that plays what the
        message asks for stamps it again). Any thread."""
        return 0

    def receive(self, size_bytes: int, *, now_s: float | None = None) -> Verdict:
        """A message of ``size_bytes`` bytes of this source arrived: check its size and rate,
        and when admitted renew the source (only a message of the source renews it: nothing
        renews a source on its behalf).

        Parameters
        ----------
        size_bytes : int, >= 0
            The message's size as it came off the wire.
        now_s : float or None
            Its arrival on the ``time.monotonic()`` clock (None: now).

        Returns
        -------
        Verdict
            Admitted (with its :class:`~phantomtouch.service.admission.Arrival`, to pass on
            to what it asks for) or dropped, and whether the drop began or sustains a flood.

        Raises
        ------
        TooLargeError
            Over the row's ``max_message_bytes`` (a WebSocket closes 1009).
        """
        self.meter.check_size(size_bytes)
        now_s = monotonic(now_s)
        verdict = self.meter.admit(now_s, self.stop_count)
        if verdict.admitted:
            self.renew(now_s)
        return verdict

    def renew(self, now_s: float | None = None) -> None:
        """A message of this source was heard (:meth:`receive` calls it for every admitted
        message; an input calls it itself only for a message that does not pass
        :meth:`receive`, such as a transport ping frame)."""
        self.last_heard_s = monotonic(now_s)

    def holds_anything(self) -> bool:
        """Whether the source holds a contact or a touch, so that it yields its slot after
        the sources holding nothing. A slot with no engine behind it cannot tell, and says
        False: among its input's sources the one silent longest yields. Any thread."""
        return False

    def close(self, reason: str = "closed") -> None:
        """The source went: let go of what it holds (:meth:`let_go`) and free its slot.
        Idempotent; any thread."""
        if self.closed:
            return
        self.closed = True
        self.let_go(reason)
        self._on_close(self)

    def let_go(self, reason: str) -> None:
        """What :meth:`close` lets go of, with ``reason``: nothing for a slot with no engine
        behind it. Any thread."""

    def yield_slot(self, reason: str) -> None:
        """The admission gives this source's slot to a newcomer: close it, then tell the
        adapter (its ``on_yield``) to end the transport. Called by :class:`Slots` only."""
        self.close("quota")
        if self._on_yield is not None:
            self._on_yield(reason)


S = TypeVar("S", bound=Slot)


@dataclass
class _Group(Generic[S]):
    """The open sources of one principal on one input, and their shared bucket."""

    rate: FloodGuard
    sources: dict[str, S] = field(default_factory=dict)


class Slots(Generic[S]):
    """The sources of every input kind of a policy table, each in a slot.

    Host, any thread: every method takes the table's lock for its own bookkeeping and
    calls a yielded source's ``on_yield`` outside it.

    Parameters
    ----------
    policies : mapping of kind to InputPolicy
        The policy table (:func:`~phantomtouch.service.admission.policy_table`); a kind
        missing from it cannot be opened.
    make : callable
        ``make(opening)``: the slot of a newcomer from its :class:`Opening` (:class:`Slot`
        itself, or a subclass).
    """

    def __init__(
        self, policies: Mapping[Kind, InputPolicy], *, make: Callable[[Opening], S]
    ) -> None:
        self._policies: dict[Kind, InputPolicy] = dict(policies)
        self._make = make
        self._lock = threading.Lock()
        self._open: dict[tuple[str, str], S] = {}
        self._owners: dict[str, S] = {}
        self._groups: dict[tuple[str, str], _Group[S]] = {}
        """The open sources of each (kind, principal), with the principal's shared bucket;
        a group goes with its last source."""
        self._counts: dict[str, int] = {}
        """Open sources by kind."""

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
    ) -> S:
        """The slot of ``source`` of input ``kind``: the one already open, or a new one.

        When the input's ``max_sources`` slots are full, or ``principal`` holds its
        ``max_sources_per_principal``, a source yields its slot (:data:`~phantomtouch.
        service.admission.policy.YIELDS`): the fair-share rule
        (:func:`~phantomtouch.engine.shares.yielding`) picks the principals that yield,
        first among principals, then among the newcomer's own principal's sources; among
        those, a source holding nothing (:meth:`Slot.holds_anything`) yields first, then the
        one silent longest. The yielded source is closed (what it holds let go of) and its
        ``on_yield(reason)`` called.

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
            ``on_yield(reason)``: end the source's transport when its slot is taken
            (:data:`YieldCallback`).
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
            slot = self._open.get(key)
            if slot is not None and not slot.closed:
                return slot
            victim = self._victim(policy, principal, local)
            if victim is not None:
                self._forget(victim)
            group = self._groups.get((kind, principal))
            if group is None:
                rate = policy.messages_per_s * policy.principal_factor
                group = self._groups[(kind, principal)] = _Group(FloodGuard(rate))
            meter = Meter(
                kind, policy.max_message_bytes, FloodGuard(policy.messages_per_s), group.rate
            )
            opening = Opening(policy, source, principal, meter, on_yield, self._closed, local)
            slot = self._make(opening)
            slot.last_heard_s = now_s
            self._open[key] = slot
            self._owners[slot.owner] = slot
            group.sources[source] = slot
            self._counts[kind] = self._counts.get(kind, 0) + 1
        if victim is not None:
            victim.yield_slot(
                f"{kind} slots full (max_sources={policy.max_sources}, "
                f"{policy.max_sources_per_principal} per host): made room for a newcomer"
            )
        return slot

    def find(self, owner: str) -> S | None:
        """The open slot named ``owner`` (``PRINCIPAL/SOURCE``), or None. Any thread,
        without the lock (a listener the engine calls may use it)."""
        return self._owners.get(owner)

    def check_size(self, kind: Kind, size_bytes: int) -> None:
        """Refuse a message of ``kind`` of ``size_bytes`` bytes over the row's
        ``max_message_bytes`` before it is read (an input whose messages name their source
        inside: a fleet contact message). Any thread.

        Raises
        ------
        TooLargeError
        """
        check_size(kind, self.policy(kind).max_message_bytes, size_bytes)

    def handles(self, kind: Kind) -> list[S]:
        """The sources of ``kind`` open now, opened first first. Any thread."""
        with self._lock:
            return [s for (k, _), s in self._open.items() if k == kind]

    def close_all(self, kind: Kind, reason: str = "closed") -> None:
        """Close every source of ``kind`` (the input stops), letting go of what they hold."""
        for slot in self.handles(kind):
            slot.close(reason)

    def _closed(self, slot: Slot) -> None:
        with self._lock:
            if self._open.get((slot.kind, slot.source)) is slot:
                self._forget(self._open[(slot.kind, slot.source)])

    def _forget(self, slot: S) -> None:
        """Take ``slot`` out of the tables (lock held)."""
        del self._open[(slot.kind, slot.source)]
        self._owners.pop(slot.owner, None)
        self._counts[slot.kind] -= 1
        group = self._groups[(slot.kind, slot.principal)]
        del group.sources[slot.source]
        if not group.sources:
            del self._groups[(slot.kind, slot.principal)]

    def _victim(self, policy: InputPolicy, principal: str, local: bool) -> S | None:
        """The source that yields its slot to a newcomer of ``principal`` (lock held), or
        None when there is room (or the newcomer is local under ``local_never_yields``).
        When the input is full some source yields if any may: the fair-share rule over the
        principals' slots (:func:`~phantomtouch.engine.shares.yielding`) picks the
        principals; when none of another principal does, one of the newcomer's own
        principal does (its sources pass the slots round), so no crowd, idle or not, locks
        a newcomer out; only sources that never yield can fill it. Among them a source
        holding nothing goes first, then the one silent longest; the cost is that of one
        principal's sources, not the input's."""
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
            s
            for p in principals
            if (g := self._groups.get((kind, p))) is not None
            for s in g.sources.values()
            if not (never and s.local)
        ]
        if not candidates:
            raise SourcesFullError(
                f"{kind}: {self._counts.get(kind, 0)} sources are open (max_sources="
                f"{policy.max_sources}, {policy.max_sources_per_principal} per host or token) "
                "and none may yield to this one; retry later",
                field="connection",
                value=self._counts.get(kind, 0),
            )
        candidates.sort(key=lambda s: s.last_heard_s)
        return next((s for s in candidates if not s.holds_anything()), candidates[0])
