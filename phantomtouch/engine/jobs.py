"""Jobs: the one table of what is playing on the host, and the front's job calls.

A job is ``scheduled``, ``playing``, then ``finished``, or ``stopped`` once a stop was
asked for (it fades out over the release); admission and fair shares: ``docs/engine.md``.
"""

from __future__ import annotations

import itertools
import threading
import uuid
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, fields
from typing import TYPE_CHECKING, Any, Literal, cast, get_args

from phantomtouch.engine.admission import Admission
from phantomtouch.engine.checks import check_ahead, check_frame, check_id
from phantomtouch.engine.messages import DropPlan, HoldPlan, ReleaseJob, StartJob
from phantomtouch.engine.owners import post_release
from phantomtouch.errors import EngineBusyError, ParameterError, PhantomTouchError
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

if TYPE_CHECKING:
    from phantomtouch.engine.engine import LocalAudio
    from phantomtouch.engine.plans import HeldPlan, PlanCache
    from phantomtouch.engine.process import ChildAudio

JobStateName = Literal["scheduled", "playing", "finished", "stopped"]
Policy = Literal["refuse", "steal-oldest", "steal-quietest"]
POLICIES: tuple[Policy, ...] = get_args(Policy)
"""What happens to a job beyond the voice budget (``docs/engine.md``)."""
HISTORY_JOBS = 1000
"""Jobs that are over and still answered by :meth:`Engine.job_state`."""
MAX_SCHEDULE_AHEAD_S = 3600.0
"""Latest start a job may ask for, s after the current frame."""
PREPARE_BLOCKS = 1
"""Blocks after the next that a job asked for as soon as possible and not prerendered is
promised: its voice is prepared outside the callback meanwhile (``docs/engine.md``)."""
_STEAL_ORDER: dict[str, Callable[[JobRecord], tuple[Any, ...]]] = {
    "steal-oldest": lambda record: (record.first_frame, record.job_id),
    "steal-quietest": lambda record: (record.amplitude, record.first_frame),
}
"""How a policy orders an owner's sounding jobs: the least is stolen first."""


@dataclass(frozen=True)
class Job:
    """A pattern accepted by :meth:`Engine.schedule`.

    Attributes
    ----------
    start_frame : int
        Frame of its first sample (for a job as soon as possible: the block it is expected
        to start in; :meth:`Engine.job_state` gives the frame it started at).
    summary : dict
        ``Plan.summary()``.
    start_at_s : float or None
        Server time, s, at which ``start_frame`` leaves the sound card, fixed when scheduled
        (:attr:`JobState.requested_start_at_s`; the clock's mapping moves as it tracks the card).
    """

    job_id: str
    start_frame: int
    frames: int
    duration_s: float
    summary: dict[str, Any] = field(hash=False)
    start_at_s: float | None = None


@dataclass(frozen=True)
class JobState:
    """Where a job is now.

    Attributes
    ----------
    start_frame : int
        Actual first frame once it started; the requested one before.
    end_frame : int
        Frame from which it is silent: ``start_frame + frames`` unless stopped, then the
        end of its release (``start_frame`` when stopped before it started).
    late : bool
        It started after its requested frame (its command arrived too late).
    reason : str or None
        Why it stopped unasked: ``stolen`` (to make room for another), or ``engine gone``
        or ``engine stalled``, ``before it played`` or ``while it played``; else None.
    """

    job_id: str
    state: JobStateName
    owner: str | None
    start_frame: int
    end_frame: int
    frames: int
    duration_s: float
    requested_start_frame: int
    late: bool
    requested_start_at_s: float | None = None
    reason: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class JobRecord:
    """The front's mutable view of one job (under its lock); ``plan`` is dropped once the
    job is over, a ``stolen`` one no longer counts against the voice budget, and one asked
    for as soon as possible (``asap``) counts against its owner's quota from its start."""

    plan: Plan | None
    job_id: str
    owner: str | None
    requested_start_frame: int
    frames: int
    duration_s: float
    amplitude: float = 1.0
    cost: float = 0.0
    """Render load while it sounds, a share of a block's playing time (0: not measured)."""
    state: JobStateName = "scheduled"
    start_frame: int | None = None
    end_frame: int | None = None
    late: bool = False
    stolen: bool = False
    requested_start_at_s: float | None = None
    reason: str | None = None
    asap: bool = False
    handle: int = field(default_factory=itertools.count(1).__next__)
    """The job's integer on the audio side, never reused."""

    @classmethod
    def planned(cls, plan: Plan, job_id: str, owner: str | None, first_frame: int) -> JobRecord:
        return cls(plan, job_id, owner, first_frame, plan.frames, plan.duration_s, plan.amplitude)

    @property
    def first_frame(self) -> int:
        return self.requested_start_frame if self.start_frame is None else self.start_frame

    @property
    def last_frame(self) -> int:
        """The frame from which it is silent (:attr:`JobState.end_frame`)."""
        return self.first_frame + self.frames if self.end_frame is None else self.end_frame

    def job(self, summary: dict[str, Any]) -> Job:
        """What :meth:`JobCalls.schedule` answers."""
        first, start_at_s = self.requested_start_frame, self.requested_start_at_s
        return Job(self.job_id, first, self.frames, self.duration_s, summary, start_at_s)

    def snapshot(self) -> JobState:
        values = {name.name: getattr(self, name.name) for name in fields(JobState)}
        values.update(start_frame=self.first_frame, end_frame=self.last_frame)
        if self.stolen and self.reason is None:
            values["reason"] = "stolen"
        return JobState(**values)


@dataclass(frozen=True)
class OwnerQuota:
    """The most one owner's jobs that are not over may hold: ``voices`` (>= 1) jobs
    scheduled or playing at once, ``seconds`` (> 0) still to play, summed over them."""

    voices: int
    seconds: float


class QuotaRefused(PhantomTouchError):
    """A job would take its owner past its ``quota`` by its ``limit`` (``voices`` or
    ``seconds``): the owner's ``jobs`` not over hold ``held_s`` s still to play, and the
    job would add ``ahead_s`` s."""

    def __init__(self, quota: OwnerQuota, limit: str, jobs: int, held_s: float, ahead_s: float):
        super().__init__(f"past the owner's {quota} by {limit}: {jobs} jobs hold {held_s:g} s")
        self.quota = quota
        self.limit = limit
        self.jobs = jobs
        self.held_s = held_s
        self.ahead_s = ahead_s


class JobTable:
    """Jobs by id: those scheduled or playing, those asked to stop (the callback has yet to
    silence them), and the last ``history`` (>= 0) that are over; ``handles``: the same by
    their integer on the audio side."""

    def __init__(self, history: int = HISTORY_JOBS) -> None:
        self.history = history
        self._live: dict[str, JobRecord] = {}
        self._stopping: dict[str, JobRecord] = {}
        self._over: OrderedDict[str, JobRecord] = OrderedDict()
        self.handles: dict[int, JobRecord] = {}

    def __len__(self) -> int:
        """Jobs scheduled or playing (not stopping, not over)."""
        return len(self._live)

    def check_quota(
        self,
        owner: str,
        quota: OwnerQuota,
        start_frame: int,
        frames: int,
        *,
        next_frame: int,
        rate_hz: int,
    ) -> None:
        """Raise :class:`QuotaRefused` if a job of ``owner`` of ``frames`` from
        ``start_frame`` would take it past ``quota``: the owner's jobs scheduled or playing
        count by their frames after ``next_frame`` (the next block's first), the new one by
        its frames from then or ``start_frame``, if later, at ``rate_hz``. A job asked for
        as soon as possible counts from its start: the blocks the engine takes to begin it
        are not its owner's."""
        ahead = [
            r.last_frame - max(next_frame, r.first_frame if r.asap else next_frame)
            for r in self._live.values()
            if r.owner == owner and r.last_frame > next_frame
        ]
        held_s = sum(ahead) / rate_hz
        ahead_s = (max(start_frame, next_frame) + frames - next_frame) / rate_hz
        if len(ahead) + 1 > quota.voices:
            raise QuotaRefused(quota, "voices", len(ahead), held_s, ahead_s)
        if held_s + ahead_s > quota.seconds:
            raise QuotaRefused(quota, "seconds", len(ahead), held_s, ahead_s)

    def admit(
        self,
        start_frame: int,
        frames: int,
        *,
        jobs: int,
        cost: float,
        budget: float,
        voices: int,
        policy: Policy,
        owner: str | None = None,
    ) -> list[JobRecord]:
        """The jobs to steal (the caller fades them out) to make room for a job of
        ``owner`` of ``frames`` from ``start_frame`` costing ``cost``, or refuse it with
        ``EngineBusyError``: when ``jobs`` are scheduled or playing, or beyond the
        ``budget`` (the costs of the jobs sounding with it, shares of a block) or
        ``voices`` unless ``policy`` steals as few as make room, fairly (``docs/engine.md``).
        """
        if len(self._live) >= jobs:
            raise EngineBusyError(
                f"the engine is full: {len(self._live)} jobs are scheduled or playing; "
                f"at most queue_capacity={jobs}"
            )
        sounding = [
            record
            for record in [*self._live.values(), *self._stopping.values()]
            if not record.stolen
            and record.first_frame < start_frame + frames
            and record.last_frame > start_frame
        ]
        load = cost + sum(record.cost for record in sounding)
        victims: list[JobRecord] = []
        steals = _fair_victims(sounding, start_frame, owner, policy)
        while not _fits(load, len(sounding) + 1 - len(victims), budget, voices):
            if (victim := next(steals, None)) is None:
                capacity = voices if cost <= 0.0 else min(voices, int(budget / cost + 1e-9))
                raise EngineBusyError(
                    f"{len(sounding)} pattern voices would sound at once from frame "
                    f"{start_frame}; the voice budget allows {max(1, capacity)} such voices "
                    f"({budget:.0%} of a block's time, at most {voices}; voice policy {policy!r})"
                )
            victims.append(victim)
            load -= victim.cost
        return victims

    def add(self, record: JobRecord) -> None:
        self._live[record.job_id] = record
        self.handles[record.handle] = record

    def get(self, job_id: str) -> JobRecord | None:
        return self._live.get(job_id) or self._stopping.get(job_id) or self._over.get(job_id)

    def mark_stopped(self, record: JobRecord, *, stolen: bool = False) -> None:
        """The job was asked to stop (or ``stolen``); the callback will silence it."""
        record.state = "stopped"
        record.stolen = record.stolen or stolen
        if self._live.pop(record.job_id, None) is not None:
            self._stopping[record.job_id] = record

    def stop_all(self) -> None:
        for record in list(self._live.values()):
            self.mark_stopped(record)

    def drop_all(self, frame: int, fault: str) -> None:
        """Every job not over is over from ``frame`` (the engine that played them is
        ``fault``: gone or stalled); each says so in its ``reason``."""
        for record in [*self._live.values(), *self._stopping.values()]:
            if record.state != "stopped":
                when = "while it played" if record.first_frame < frame else "before it played"
                record.reason = f"engine {fault} {when}"
            record.state = "stopped"
            record.end_frame = max(frame, record.first_frame)
            self.retire(record)

    def retire(self, record: JobRecord) -> None:
        """Move a job that is over into the bounded history."""
        record.plan = None
        self._live.pop(record.job_id, None)
        self._stopping.pop(record.job_id, None)
        self._over[record.job_id] = record
        while len(self._over) > self.history:
            self.handles.pop(self._over.popitem(last=False)[1].handle, None)


def resolve_plan(pattern: TouchPattern | Plan, device: DeviceProfile) -> Plan:
    """The plan of a pattern for ``device`` (a given plan must be made for ``device``).

    Raises
    ------
    ParameterError
        The pattern cannot be planned, or the plan is for another device.
    """
    if isinstance(pattern, Plan):
        if pattern.device != device:
            raise ParameterError(
                f"pattern is a Plan for device {pattern.device.name!r} at "
                f"{pattern.sample_rate_hz} Hz; plan it for this engine's device"
            )
        return pattern
    if isinstance(pattern, TouchPattern):
        return plan(pattern, device)
    raise ParameterError(f"pattern must be a TouchPattern or a Plan, got {type(pattern).__name__}")


def _fair_victims(
    sounding: list[JobRecord], start_frame: int, owner: str | None, policy: Policy
) -> Iterator[JobRecord]:
    """Jobs to steal, in turn, max-min fair (``docs/owners.md``); none under ``refuse``."""
    if policy == "refuse":
        return
    held = Counter(record.owner for record in sounding)
    held[owner] += 1
    order = _STEAL_ORDER[policy]
    candidates: dict[str | None, list[JobRecord]] = {}
    for record in sorted(sounding, key=order, reverse=True):
        if record.first_frame <= start_frame and record.state != "stopped":
            candidates.setdefault(record.owner, []).append(record)
    while True:
        most = max(held.values())
        largest = [owner] if held[owner] == most else [o for o, n in held.items() if n == most]
        ready = [o for o in largest if candidates.get(o)]
        if not ready:
            return
        holder = min(ready, key=lambda o: order(candidates[o][-1]))
        held[holder] -= 1
        yield candidates[holder].pop()


def _fits(load: float, count: int, budget: float, voices: int) -> bool:
    """Within ``voices``, and within the ``budget`` (one voice alone always fits it)."""
    return count <= voices and (count <= 1 or load <= budget * (1.0 + 1e-9))


class JobCalls:
    """The job methods of :class:`~phantomtouch.engine.front.EngineFront`, which makes
    the state below; every method runs in the host, on any thread."""

    plans: PlanCache
    device: DeviceProfile
    _lock: threading.RLock
    _audio: LocalAudio | ChildAudio
    _jobs: JobTable
    _admission: Admission
    _policy: Policy
    _queue_capacity: int
    _steal_fade_frames: int
    _stop_count: int

    @staticmethod
    def _check_policy(policy: object) -> Policy:
        if policy not in POLICIES:
            raise ParameterError(f"voice_policy={policy!r} must be one of {list(POLICIES)}")
        return cast(Policy, policy)

    @property
    def voice_capacity(self) -> int:
        """Pattern voices that may sound at once (:class:`Admission`; host, any thread)."""
        return self._admission.voice_capacity

    @property
    def starts_per_block(self) -> int:
        """Pattern voices that may begin in one block (:class:`Admission`); host, any
        thread."""
        return self._admission.starts_per_block

    @property
    def stop_count(self) -> int:
        """How many times ``stop_all`` was called (host, any thread)."""
        return self._stop_count

    def schedule(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
        policy: Policy | None = None,
        stop_count: int | None = None,
        quota: OwnerQuota | None = None,
    ) -> Job:
        """Play a pattern from ``start_frame`` on, sample-exact (host, any thread).

        Parameters
        ----------
        pattern : TouchPattern or Plan
            A plan must be made for this engine's device.
        start_frame : int or None
            Frame of its first sample, at most ``MAX_SCHEDULE_AHEAD_S`` ahead; one passed
            when the command arrives starts at once (``late_commands``). None: as soon as
            possible (:data:`PREPARE_BLOCKS`).
        owner : str or None
            The client it belongs to (1-64 characters), for the log, fair shares, ``quota``.
        policy : {"refuse", "steal-oldest", "steal-quietest"} or None
            Beyond the voice budget (None: the engine's ``voice_policy``).
        stop_count : int or None
            :attr:`stop_count` when the request arrived: if ``stop_all`` was called
            since, the job is void (accepted as ``stopped``; it never plays).
        quota : OwnerQuota or None
            The most ``owner``'s jobs not over may hold, this one included; None: no bound.

        Returns
        -------
        Job

        Raises
        ------
        ParameterError
            The pattern cannot be planned, or an argument is out of range.
        QuotaRefused
            The job would take ``owner`` past ``quota``.
        EngineBusyError
            ``queue_capacity`` jobs are scheduled or playing, or the voice budget is full.
        DeviceError
            The engine is closed, or its audio side is not running.
        """
        entry = self.plans.entry(pattern)
        resolved, prerendered = entry.plan, entry.prerendered
        frame = check_frame("start_frame", start_frame)
        if owner is not None:
            check_id("owner", owner)
        elif quota is not None:
            raise ParameterError("quota counts the jobs of an owner: give owner")
        chosen = self._policy if policy is None else self._check_policy(policy)
        rate_hz = self.device.sample_rate_hz
        if frame is not None:
            check_ahead(frame, self._audio.now_frames, rate_hz, MAX_SCHEDULE_AHEAD_S)
        job_id = uuid.uuid4().hex
        carrier = None if prerendered is not None else resolved.pattern.carrier
        self._audio.prepare(carrier)
        with self._lock:
            self._audio.check_ready()
            next_frame = self._audio.next_block_frame()
            prepare = 0 if prerendered is not None else PREPARE_BLOCKS * self.device.block_frames
            first = next_frame + prepare if frame is None else frame
            record = JobRecord.planned(resolved, job_id, owner, first)
            record.asap = frame is None
            if owner is not None and quota is not None:
                asked = next_frame if record.asap else first
                self._jobs.check_quota(
                    owner, quota, asked, record.frames, next_frame=next_frame, rate_hz=rate_hz
                )
            if stop_count is not None and stop_count != self._stop_count:
                record.state, record.end_frame = "stopped", first
                self._jobs.retire(record)
                return record.job(resolved.summary())
            record.cost = self._admission.cost(prerendered is not None)
            victims = self._jobs.admit(
                first,
                resolved.frames,
                jobs=self._queue_capacity,
                cost=record.cost,
                budget=self._admission.render_budget,
                voices=self._admission.max_voices,
                policy=chosen,
                owner=owner,
            )
            if prerendered is None:  # a prerendered one renders nothing in the callback
                first = self._admission.begin(first, frame is None, self._audio.now_frames)
                record.requested_start_frame = frame = first  # the promised frame, not sooner
            record.requested_start_at_s = self._audio.time_at(first)  # one value for all
            self._audio.provide(carrier)
            self._start(entry, StartJob(record.handle, entry.handle, frame))
            for victim in victims:
                self._jobs.mark_stopped(victim, stolen=True)
                victim.end_frame = max(first, victim.first_frame) + self._steal_fade_frames
                post_release(self._audio, ReleaseJob(victim.handle, first, self._steal_fade_frames))
            self._jobs.add(record)
        return record.job(resolved.summary())

    def _start(self, entry: HeldPlan, start: StartJob) -> None:
        """Hand the plan over unless held, post ``start``, release what the cache dropped."""
        if not entry.handed:
            self._audio.post(HoldPlan(entry.handle, entry.plan, entry.prerendered))
            entry.handed = True
        self._audio.post(start)
        dropped = self.plans.take_dropped()
        if not entry.kept:
            dropped.append(entry)
        for old in dropped:
            if old.handed:
                self.plans.release(old)
                self._audio.post(DropPlan(old.handle))

    async def schedule_async(self, pattern: TouchPattern | Plan, **options: Any) -> Job:
        """:meth:`schedule` for a coroutine, with its keywords (host, the event loop; it
        never waits for the audio side)."""
        return self.schedule(pattern, **options)

    def job_state(self, job_id: str) -> JobState | None:
        """The state of a job, or None if unknown (or too old: the last 1000 are kept);
        host, any thread."""
        self._audio.sync()
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            return None if record is None else record.snapshot()

    def stop(self, job_id: str) -> bool:
        """Stop a job: it fades out over ``contact.release_s`` (or never starts); host,
        any thread. Returns False if the job is unknown or already over."""
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            if record is None or record.state in ("finished", "stopped"):
                return False
            post_release(self._audio, ReleaseJob(record.handle, None, None))
            self._jobs.mark_stopped(record)
            return True
