"""Every command the audio side takes, each with its one applier (``apply``), and every
event it reports, each one typed (docs/engine.md, Messages)."""

from __future__ import annotations

import copyreg
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, get_args

import numpy as np

from phantomtouch.engine.plan_memory import SHARE_MIN_BYTES, SharedArrays, heavy_bytes
from phantomtouch.engine.prerender import Prerendered
from phantomtouch.renderer.carriers import CarrierSource, NoiseKey, make_source
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.pattern import CombinedCarrier, NoiseCarrier, SineCarrier

if TYPE_CHECKING:
    from phantomtouch.engine.core import Core
    from phantomtouch.engine.noise import HeldLoops
    from phantomtouch.engine.plan_memory import HeldArrays
    from phantomtouch.engine.shared import MoveSlots
    from phantomtouch.engine.voices import PatternVoice

# -- commands, front -> audio side, each with its applier ------------------------------


@dataclass(frozen=True, slots=True)
class HoldPlan:
    """Hold a plan under ``handle`` (minted by the front's plan cache) until a
    :class:`DropPlan`; ``prerendered`` is its samples rendered whole, or None to render
    them in the callback. ``shared`` (engine process): the block of shared memory that
    holds the plan's heavy arrays (:mod:`phantomtouch.engine.plan_memory`)."""

    handle: int
    plan: Plan
    prerendered: Prerendered | None
    shared: SharedArrays | None = None

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time. Keep the plan (even when void: it was handed once), its heavy arrays
        mapped from the host's block; in the engine process, refuse heavy arrays inline."""
        plan, prerendered, handle, arrays = self.plan, self.prerendered, self.handle, state.arrays
        if self.shared is not None:
            try:
                if arrays is None:
                    raise LookupError("this audio side maps no shared plans")
                plan, prerendered = arrays.hold(handle, plan, self.shared)
            except (LookupError, OSError) as exc:
                state.refuse("plan", handle, f"plan {handle}: {exc}")
                return
        elif arrays is not None and (size := heavy_bytes(plan, prerendered)) >= SHARE_MIN_BYTES:
            state.refuse("plan", handle, f"plan {handle} carries {size} bytes inline")
            return
        state.plans[handle] = (state.core.widen(plan), prerendered)


@dataclass(frozen=True, slots=True)
class DropPlan:
    """Release the plan of ``handle`` (reported as :class:`PlanReleased`); voices that
    play it keep it to their end."""

    handle: int

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time. Forget the plan; its block is released once no voice reads it."""
        state.plans.pop(self.handle, None)
        if state.arrays is None or not state.arrays.drop(self.handle):
            state.reports.append(PlanReleased(self.handle))


@dataclass(frozen=True, slots=True)
class StartJob:
    """Play the plan held under ``plan_key`` as ``job`` (the front's integer for the job)
    from ``frame`` (None: the next block)."""

    job: int
    plan_key: int
    frame: int | None

    def prepare(self, state: AudioState) -> StartVoice:
        """Non real time (see :func:`prepare`): build the voice of a plan held, or refuse it."""
        held = state.plans.get(self.plan_key)
        try:
            if held is None:
                raise LookupError(f"plan {self.plan_key} was not handed over")
            return StartVoice(self, state.core.job_voice(self.job, held[0], held[1]))
        except LookupError as exc:  # a plan or a noise loop not handed over
            state.refuse("plan" if held is None else "noise loop", self.job, str(exc))
            return StartVoice(self, None)

    def apply(self, state: AudioState, void: bool) -> None:
        """Non real time: the caller's thread (the in-process engine; the engine process
        before its sink starts) prepares and starts it at once."""
        self.prepare(state).apply(state, void)


@dataclass(frozen=True, slots=True)
class StartVoice:
    """A :class:`StartJob` prepared by :func:`prepare`: its voice built (None: refused).
    Made by the audio side, never sent by the host."""

    start: StartJob
    voice: PatternVoice | None

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time. Start the voice; a void or refused start is reported cancelled."""
        core, voice = state.core, self.voice
        if voice is not None and not void:
            core.start_job(voice, self.start.frame)
            return
        if voice is not None:
            voice.finish(core.scheduler.pool)
        state.reports.append(Cancelled("job", self.start.job, core.scheduler.frames))


@dataclass(frozen=True, slots=True)
class ReleaseJob:
    """Fade a job out from ``frame`` (None: the next block) over ``fade_frames`` (None:
    the contact settings' ``release_s``)."""

    job: int
    frame: int | None
    fade_frames: int | None

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time."""
        if not void:
            state.core.release_job(self.job, self.frame, self.fade_frames)


@dataclass(frozen=True, slots=True)
class ContactDown:
    """A touchdown, checked and computed by the front: the audio side only builds the
    voice from these parts.

    ``contact`` is the front's integer for the contact; ``unit_gains`` (shape (channels,),
    float32) are the phantom gains of the position (projected onto the layout), ``amplitude``
    the voice's linear amplitude, ``burst`` the impact transient's samples (or None); ``slot``
    and ``generation`` name the engine process's shared-memory move slot (None here).
    """

    contact: int
    x_cm: float
    y_cm: float
    unit_gains: np.ndarray
    amplitude: float
    carrier: SineCarrier | NoiseCarrier | CombinedCarrier
    law: str
    burst: np.ndarray | None
    frame: int | None
    slot: int | None = None
    generation: int = 0

    def prepare(self, state: AudioState) -> StartContact:
        """Non real time (the engine process's inbox thread, or whoever performs it): the
        carrier's source from the noise loops held now, or refused (a loop not handed)."""
        try:
            return StartContact(self, make_source(self.carrier, state.core.device.sample_rate_hz))
        except LookupError as exc:
            state.refuse("noise loop", self.contact, str(exc))
            return StartContact(self, None)

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time in this process: prepared and started at once."""
        self.prepare(state).apply(state, void)


@dataclass(frozen=True, slots=True)
class StartContact:
    """A :class:`ContactDown` prepared by :func:`prepare`: its carrier's source made
    (None: refused). Made by the audio side, never sent by the host."""

    down: ContactDown
    source: CarrierSource | None

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time."""
        down = self.down
        if void or self.source is None:
            return
        state.core.board.down(down, self.source)
        if state.slots is not None and down.slot is not None:
            state.slots.bind(down.slot, down.generation, down.contact)


@dataclass(frozen=True, slots=True)
class ContactMove:
    """A contact's newest position, checked by the front, as its phantom gains
    (``unit_gains``, shape (channels,), float32, projected onto the layout: computed by the
    front, so the callback only ramps to them); in-process engine only: the engine process
    takes moves from shared memory."""

    contact: int
    unit_gains: np.ndarray
    intensity: float | None
    frame: int | None

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time."""
        if not void:
            state.core.board.post_checked(self.contact, self.unit_gains, self.intensity, self.frame)


@dataclass(frozen=True, slots=True)
class ContactUp:
    """Lift-off of ``contacts`` (the front's integers: one contact, or every contact of an
    owner) from ``frame`` (None: the next block), each with a transient ``burst`` or None."""

    contacts: tuple[int, ...]
    burst: np.ndarray | None
    frame: int | None

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time."""
        if void:
            return
        if state.slots is not None:
            state.slots.unbind(self.contacts)
        for contact in self.contacts:
            state.core.board.up(contact, self.burst, self.frame)


RELEASES = (ReleaseJob, ContactUp)
"""Commands that end a sound: never refused for room (``link.Outbox.put``)."""


@dataclass(frozen=True, slots=True)
class HoldNoise:
    """A noise loop the host wrote into the shared memory named ``name``: use it for
    ``key`` until :class:`DropNoise`."""

    key: NoiseKey
    name: str

    def apply(self, state: AudioState, void: bool) -> None:
        """Non real time (the engine process's inbox thread, :func:`prepare`): map the
        host's shared memory (no copy, nothing computed)."""
        if state.loops is None:
            state.refuse("noise loop", self.key, "this audio side takes no shared loops")
            return
        state.loops.hold(self.key, self.name)


@dataclass(frozen=True, slots=True)
class DropNoise:
    """Stop using the noise loop of ``key``; report :class:`NoiseReleased` once no voice
    reads it any more, so that the host may free it."""

    key: NoiseKey

    def apply(self, state: AudioState, void: bool) -> None:
        """Non real time (the engine process's inbox thread, :func:`prepare`, in order with
        the holds and the sources it makes)."""
        if state.loops is not None:
            state.loops.drop(self.key)


@dataclass(frozen=True, slots=True)
class SetWearerGains:
    """The wearer's per-channel gains at the output stage from the next block on, ramped
    across it (:class:`~phantomtouch.engine.mixer.WearerGains`); ``gains`` (shape
    (channels,), float32, finite, > 0) checked by the front; all ones: no wearer."""

    gains: np.ndarray

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time: leave the gains for the next block (kept even when void: a stop does not
        take the wearer off)."""
        state.core.scheduler.mixer.wearer.set(self.gains)


@dataclass(frozen=True, slots=True)
class StartSink:
    """Start playing (engine process, before its first block)."""

    def apply(self, state: AudioState, void: bool) -> None:
        """Non real time, and nothing to do: the engine process's main thread takes it
        before its first block and starts the sink (``child._wait_for_start``)."""


@dataclass(frozen=True, slots=True)
class Close:
    """Fade out and end (engine process)."""

    def apply(self, state: AudioState, void: bool) -> None:
        """Real time: the engine process's main thread fades out and ends."""
        state.leave = True


Command = (
    HoldPlan
    | DropPlan
    | StartJob
    | StartVoice
    | ReleaseJob
    | ContactDown
    | StartContact
    | ContactMove
    | ContactUp
    | HoldNoise
    | DropNoise
    | SetWearerGains
    | StartSink
    | Close
)

# -- events, audio side -> front ----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class VoiceEvent:
    """What a voice did at ``frame``: ``kind`` "job" or "contact", ``key`` the integer the
    front minted for it (the front alone maps it back to a job id or an owner's contact)."""

    kind: str
    key: int
    frame: int


@dataclass(frozen=True, slots=True)
class Started(VoiceEvent):
    """A voice began at ``frame`` (``late``: its frame had passed). A contact's carries
    its touchdown position and amplitude."""

    late: bool
    x_cm: float | None = None
    y_cm: float | None = None
    amplitude: float | None = None


@dataclass(frozen=True, slots=True)
class Released(VoiceEvent):
    """A voice's fade-out begins at ``frame``; it is silent from ``silent_from``."""

    silent_from: int | None


@dataclass(frozen=True, slots=True)
class Ended(VoiceEvent):
    """A voice is silent from ``frame``."""


@dataclass(frozen=True, slots=True)
class Cancelled(VoiceEvent):
    """A voice was voided before it started."""


@dataclass(frozen=True, slots=True)
class StoppedAll:
    """Everything began fading out at ``frame``."""

    frame: int


@dataclass(frozen=True, slots=True)
class NoiseReleased:
    """The engine process no longer reads the noise loop of ``key``: the host may free it."""

    key: NoiseKey


@dataclass(frozen=True, slots=True)
class PlanReleased:
    """The audio side no longer holds the plan of ``handle``."""

    handle: int


@dataclass(frozen=True, slots=True)
class Refused:
    """The audio side refused a command whose data it was not handed (``what``: "plan",
    "noise loop"), or that failed; ``key``: the plan, job or contact's integer, or the loop's."""

    what: str
    key: Any
    reason: str


Event = Started | Released | Ended | Cancelled | StoppedAll | NoiseReleased | PlanReleased | Refused


_FIELD_NAMES: dict[type, tuple[str, ...]] = {
    kind: tuple(f.name for f in fields(kind)) for kind in (*get_args(Command), *get_args(Event))
}


def _pickled(message: Any) -> tuple[type, tuple[Any, ...]]:
    """A command or event as pickle takes it: its class and its fields' values, which the
    class's ``__init__`` takes in that order (a slotted dataclass's own ``__getstate__``
    and ``__setstate__`` look its fields up again for every message, a third of the
    pickling time of a block's events)."""
    kind = type(message)
    return kind, tuple([getattr(message, name) for name in _FIELD_NAMES[kind]])


for _kind in _FIELD_NAMES:
    copyreg.pickle(_kind, _pickled)

# -- the audio side's state and the table of appliers -------------------------------


@dataclass
class AudioState:
    """What the appliers act on: the core, and in the engine process the move slots,
    the plans and noise loops it was handed, and events of its own to report."""

    core: Core
    slots: MoveSlots | None = None
    loops: HeldLoops | None = None
    arrays: HeldArrays | None = None
    plans: dict[int, tuple[Plan, Prerendered | None]] = field(default_factory=dict)
    reports: list[Event] = field(default_factory=list)
    refused: int = 0
    leave: bool = False

    def refuse(self, what: str, key: Any, reason: str) -> None:
        """Count and report a refusal (real time)."""
        self.refused += 1
        self.reports.append(Refused(what, key, reason))


APPLIERS: dict[type, Callable[[Any, AudioState, bool], None]] = {
    kind: kind.apply for kind in get_args(Command)
}
"""Each command's applier (its ``apply``), by the command's class."""


def prepare(state: AudioState, message: Command) -> Command | None:
    """Do the heavy part of a command before the callback sees it, in the order the commands
    came (non real time: the engine process's inbox thread; docs/engine.md, Threads).
    Returns what is left to :func:`perform`, None for nothing."""
    if isinstance(message, HoldPlan | HoldNoise | DropNoise):
        perform(state, message)
        return None
    return message.prepare(state) if isinstance(message, StartJob | ContactDown) else message


def perform(state: AudioState, message: Command, *, void: bool = False) -> None:
    """Apply one command (real time in the engine process).

    ``void``: the command was sent before a ``stop_all`` the audio side has seen; its
    applier keeps what must outlive it (a plan, a noise loop) and plays nothing.
    """
    APPLIERS[type(message)](message, state, void)
