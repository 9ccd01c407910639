"""The engine's front: its API and every fact the host keeps, over one audio side
(``docs/engine.md``)."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Self

from phantomtouch.engine.checks import check_channel_gains, check_int, check_range, check_seconds
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.events import apply_events
from phantomtouch.engine.job_calls import JobCalls
from phantomtouch.engine.job_ids import JobIds
from phantomtouch.engine.jobs import JobTable, Policy
from phantomtouch.engine.messages import Event, PlanReleased, SetWearerGains
from phantomtouch.engine.owners import ContactCalls, DeadlineThread, OwnerTable
from phantomtouch.engine.plans import PlanCache
from phantomtouch.engine.prerender import PRERENDER_MAX_S
from phantomtouch.engine.render_budget import RENDER_BUDGET, Admission
from phantomtouch.engine.status import EngineStatus
from phantomtouch.engine.touchdown import Touchdowns
from phantomtouch.errors import ParameterError
from phantomtouch.schema.device import DeviceProfile

if TYPE_CHECKING:
    from phantomtouch.engine.local_audio import LocalAudio
    from phantomtouch.engine.process import ChildAudio

MAX_QUEUE_CAPACITY = 1_000_000
MAX_VOICES = 64
"""Default of ``max_voices``."""
STEAL_FADE_S = 0.005
"""Fade-out of a stolen job, s."""
_CASTS: dict[str, Callable[[Any], Any]] = {"int": int, "float": float, "str": str, "bool": bool}
"""A status field's type made of the audio side's figure (numpy scalars to Python's)."""


@dataclass(frozen=True)
class Links:
    """What an audio side gets from the front that makes it: the checked arguments it
    needs, ``deliver(events)`` (its events to the front) and ``lost(state)`` (it died or
    stalled: everything it played is gone)."""

    settings: ContactSettings
    queue_capacity: int
    max_voices: int
    costs: tuple[float, float, float] | None
    deliver: Callable[[list[Event]], None]
    lost: Callable[[str], None]


class StimulusLog:
    """Appends the stimulus log's JSON lines (``docs/engine.md``) to a file (host, any
    thread; never the audio callback).

    Parameters
    ----------
    path : str or Path
        Created if missing; appended to otherwise.

    Raises
    ------
    ParameterError
        The file cannot be opened for appending.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._file: IO[str] | None = self.path.open("a", encoding="utf-8")
        except OSError as exc:
            raise ParameterError(
                f"log_path={str(path)!r} cannot be opened for appending: {exc.strerror}"
            ) from exc
        self._lock = threading.Lock()

    def write(self, records: list[dict[str, Any]]) -> None:
        """Append records, one line each, and flush; nothing once closed."""
        text = "".join(json.dumps(record, separators=(",", ":")) + "\n" for record in records)
        with self._lock:
            if self._file is not None and text:
                self._file.write(text)
                self._file.flush()

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None


class EngineFront(JobCalls, ContactCalls):
    """The engine's API and the host's state, over one audio side.

    Parameters
    ----------
    device : DeviceProfile
    audio : callable
        ``audio(links)`` makes the audio side (:class:`Links`), once the arguments below
        were checked; its ``device`` (the profile at the block its sink found, the sound
        card's period) is the engine's :attr:`device`.
    queue_capacity : int, 1 <= queue_capacity <= 1_000_000
        Most jobs scheduled or playing at once, and most voices waiting to start.
    max_voices : int, 1 <= max_voices <= 1_000_000
        Most pattern voices that may sound at once, whatever the budget allows.
    contact : ContactSettings or None
    log_path : str, Path or None
        Append the stimulus log (JSON lines, :class:`StimulusLog`) here.
    render_budget : float, 0 < render_budget <= 1
        Share of a block's playing time pattern voices may take (``RENDER_BUDGET``).
    voice_policy : {"refuse", "steal-oldest", "steal-quietest"}
        What a job beyond the budget does (:data:`~phantomtouch.engine.jobs.POLICIES`).
    prerender_max_s : float, 0 <= prerender_max_s <= 10
        Plans at most this long, s, are rendered whole when scheduled
        (:mod:`phantomtouch.engine.prerender`); 0: every plan renders in the callback.
    voice_cost, start_cost : float or None, 1e-6 <= cost <= 100
        Render load of one sounding pattern voice, and what one adds to the block it
        begins in, shares of a block; None: measured by the audio side (a ``voice_cost``
        given alone leaves the starts per block unbounded).
    """

    def __init__(
        self,
        device: DeviceProfile,
        audio: Callable[[Links], LocalAudio | ChildAudio],
        *,
        queue_capacity: int = 4096,
        max_voices: int = MAX_VOICES,
        contact: ContactSettings | None = None,
        log_path: str | Path | None = None,
        render_budget: float = RENDER_BUDGET,
        voice_policy: Policy = "steal-oldest",
        prerender_max_s: float = PRERENDER_MAX_S,
        voice_cost: float | None = None,
        start_cost: float | None = None,
    ) -> None:
        if not isinstance(device, DeviceProfile):
            raise ParameterError(f"device={device!r} must be a DeviceProfile")
        check_int("queue_capacity", queue_capacity, 1, MAX_QUEUE_CAPACITY)
        check_int("max_voices", max_voices, 1, MAX_QUEUE_CAPACITY)
        check_range("render_budget", render_budget, 1e-3, 1.0, "(share of a block)")
        check_range("prerender_max_s", prerender_max_s, 0.0, 10.0, "s")
        if contact is not None and not isinstance(contact, ContactSettings):
            raise ParameterError(f"contact={contact!r} must be ContactSettings or None")
        for name, cost in (("voice_cost", voice_cost), ("start_cost", start_cost)):
            if cost is not None:
                check_range(name, cost, 1e-6, 100.0, "")
        costs = None  # measured by the audio side, unless given
        if voice_cost is not None or start_cost is not None:
            costs = (voice_cost or 0.0, start_cost or 0.0, voice_cost or 0.0)
        settings = contact or ContactSettings()
        self._queue_capacity = queue_capacity
        self._policy = self._check_policy(voice_policy)
        self._lock = threading.RLock()
        self._jobs = JobTable()
        self._job_ids = JobIds()
        self._contacts = OwnerTable(settings.max_contacts)
        self._listeners = []
        self._deadlines = DeadlineThread(self._expire_deadlines)
        self._stop_count = 0
        self._log = StimulusLog(log_path) if log_path is not None else None
        self._audio: LocalAudio | ChildAudio = audio(
            Links(settings, queue_capacity, max_voices, costs, self._apply_events, self._lost)
        )
        device = self._audio.device  # at the block the sink found: the sound card's period
        self.device = device
        """The device profile at the engine's block, and its figures below (host, any
        thread)."""
        self.sample_rate_hz = device.sample_rate_hz
        self.block_frames = device.block_frames
        self.channels = device.channels
        self._admission = Admission(device, max_voices=max_voices, render_budget=render_budget)
        self._steal_fade_frames = max(1, round(STEAL_FADE_S * device.sample_rate_hz))
        self.plans = PlanCache(device, prerender_max_s=prerender_max_s)
        """The one plan cache (host, any thread): the service plans through it."""
        self._touchdowns = Touchdowns(device, settings)
        self._admission.take_costs(self._audio.costs)

    def start(self) -> None:
        """Start playing (no-op when playing): measure a voice's cost if the audio side
        must, start its sink and wait until it plays; host, any thread.

        Raises
        ------
        DeviceError
            The engine is closed, or the audio side cannot start.
        """
        self._audio.start()
        self._admission.take_costs(self._audio.costs)

    def close(self) -> None:
        """Fade everything out, close the audio side, flush the log. Idempotent; host,
        any thread."""
        try:
            self._audio.close()
        finally:
            if self._log is not None:
                self._log.close()

    @property
    def now_frames(self) -> int:
        """The sample clock: frames handed to the sink so far (host, any thread)."""
        return self._audio.now_frames

    def frames_at(self, server_time_s: float) -> int:
        """The frame that leaves the sound card at ``server_time_s`` (server clock; host,
        any thread)."""
        return self._audio.frames_at(check_seconds("server_time_s", server_time_s))

    def time_at(self, frame: int) -> float:
        """Server time, s, at which ``frame`` leaves the sound card (host, any thread)."""
        return self._audio.time_at(check_int("frame", frame, -(1 << 62), 1 << 62))

    def _lost(self, state: str) -> None:
        """The audio side is gone or stalled: all it played is over (host, the watchdog)."""
        with self._lock:
            self._jobs.drop_all(self.now_frames, fault=state)
            self.plans.unhand_all()
            owners = self._contacts.pop_all()
            self._admission.forget_starts()
        self._publish(owners, f"engine {state}")

    def server_time_s(self) -> float:
        """The server clock, s (``time.monotonic()``, the same in every process; host,
        any thread)."""
        return time.monotonic()

    def stop_all(self) -> None:
        """Everything off: every job and contact fades out, each contact published as
        ``released`` with reason ``stop`` (host, any thread). Never refused, never waits:
        jobs and touchdowns accepted before it never start, whatever the audio side's state.
        """
        with self._lock:
            self._stop_count += 1
            owners = self._contacts.pop_all()
            self._jobs.stop_all()
            for held in owners.values():
                for record in held.values():
                    self._audio.free_slot(record.slot)
            self._audio.stop_all()
        self._publish(owners, "stop")

    def _apply_events(self, events: list[Event]) -> None:
        """Apply the audio side's events, then write the log records due (host: the
        housekeeping thread, or the thread reading the engine process's reports)."""
        with self._lock:
            for event in events:
                if isinstance(event, PlanReleased):
                    self.plans.released(event.handle)
            records = apply_events(
                self._jobs, self._contacts.names, events, self.time_at if self._log else None
            )
        if self._log is not None:
            self._log.write(records)

    def status(self) -> EngineStatus:
        """A snapshot of clock, voices, levels and counters (host, any thread); never
        waits for the audio side (its figures are at most a block old)."""
        figures = self._audio.figures()
        with self._lock:
            contacts = [
                {"owner": owner, "contact": contact, "x_cm": r.x_cm, "y_cm": r.y_cm}
                for owner, contact, r in self._contacts.items()
            ]
        values: dict[str, Any] = {"restarts": 0, **figures}
        values.update(
            sample_rate_hz=self.sample_rate_hz,
            block_frames=self.block_frames,
            channels=self.channels,
            active_contacts=contacts,
            queue_capacity=self._queue_capacity,
            voice_capacity=self.voice_capacity,
            voice_cost=self._admission.voice_cost,
            start_cost=self._admission.start_cost,
            starts_per_block=min(self.starts_per_block, 1 << 20),
            render_budget=self._admission.render_budget,
        )
        return EngineStatus(
            **{
                field.name: _CASTS.get(str(field.type), lambda value: value)(values[field.name])
                for field in fields(EngineStatus)
            }
        )

    def set_wearer_gains(self, gains: object) -> None:
        """Scale each output channel by ``gains`` from the next block on, ramped across
        that block and kept across stops and engine restarts (host, any thread; where in
        the output stage: ``docs/engine.md``).

        Parameters
        ----------
        gains : array_like, shape (channels,)
            Linear gains, finite and > 0 (a wearer's offset of ``d`` dB is
            ``10 ** (d / 20)``).

        Raises
        ------
        ParameterError
            ``gains`` has the wrong shape or a value not finite or not > 0.
        EngineBusyError
            The engine process is not taking commands.
        """
        checked = check_channel_gains("gains", gains, self.channels)
        with self._lock:
            self._audio.post(SetWearerGains(checked))

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
