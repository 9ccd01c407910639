"""The admission: the sources of every input as :class:`~phantomtouch.service.admission.
Handle`\\ s in the slots of :class:`~phantomtouch.service.admission.slots.Slots`, over one
engine."""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from phantomtouch.service.admission.handle import Handle
from phantomtouch.service.admission.policy import InputPolicy, Kind
from phantomtouch.service.admission.rate import Arrival, monotonic
from phantomtouch.service.admission.slots import Slots

KindListener = Callable[[Handle, tuple[str, ...], str], None]
"""``listener(handle, contacts, reason)``: the front let go of ``contacts`` of ``handle``'s
source without an ``up`` (:meth:`Admission.on_released`)."""

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront
    from phantomtouch.service.store import PatternStore


class Admission(Slots[Handle]):
    """The one admission of a service: every input opens its sources here
    (:meth:`~phantomtouch.service.admission.slots.Slots.open`) and does everything through
    their :class:`~phantomtouch.service.admission.Handle`.

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
        super().__init__(policies, make=functools.partial(Handle, engine, store))
        self.engine = engine
        self.store = store
        self._serial = itertools.count(1)

    def new_source(self) -> str:
        """A source name never given before by this admission, for an input whose sources
        have no name of their own (a WebSocket connection). Any thread."""
        return f"c{next(self._serial)}"

    def arrival(self) -> Arrival:
        """An :class:`~phantomtouch.service.admission.Arrival` for now: for a message an
        input reads before it knows its source (a fleet touch names its client inside).
        Any thread."""
        return Arrival(self.engine.stop_count, monotonic(None))

    def on_released(self, kind: Kind, listener: KindListener) -> Callable[[], None]:
        """Call ``listener(handle, contacts, reason)`` whenever the front lets go of
        contacts of an open source of ``kind`` without an ``up``, in the releasing thread
        (it must return at once and must not call the front back); returns the function
        that unsubscribes it. Any thread."""

        def released(owner: str, contacts: tuple[str, ...], reason: str) -> None:
            handle = self.find(owner)
            if handle is not None and handle.kind == kind:
                listener(handle, contacts, reason)

        return self.engine.subscribe_released(released)

    def stop_all(self) -> None:
        """The emergency stop: every touch and contact of every input off at once (never
        queued); whatever a source sent before it is void, also what is still being
        planned (:class:`~phantomtouch.service.admission.Arrival`). Any thread."""
        self.engine.stop_all()
