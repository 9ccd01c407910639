"""Jobs: the one table of what is playing on the host (the front's job calls over it:
:mod:`phantomtouch.engine.job_calls`).

A job is ``scheduled``, ``playing``, then ``finished``, or ``stopped`` once a stop was
asked for (it fades out over the release); admission and fair shares: ``docs/engine.md``.
"""

from __future__ import annotations

import itertools
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Literal, get_args

from phantomtouch.engine.shares import yielding
from phantomtouch.errors import EngineBusyError, PhantomTouchError
from phantomtouch.renderer.plan import Plan

JobStateName = Literal["scheduled", "playing", "finished", "stopped"]
Policy = Literal["refuse", "steal-oldest", "steal-quietest"]
POLICIES: tuple[Policy, ...] = get_args(Policy)
"""What happens to a job beyond the voice budget (``docs/engine.md``)."""
_STEAL_ORDER: dict[str, Callable[[JobRecord], tuple[Any, ...]]] = {
    "steal-oldest": lambda record: (record.first_frame, record.job_id),
    "steal-quietest": lambda record: (record.amplitude, record.first_frame),
}
"""How a policy orders an owner's sounding jobs: the least is stolen first."""
HISTORY_JOBS = 1000
"""Jobs that are over and still answered by :meth:`Engine.job_state`, per owner."""
HISTORY_OWNERS = 10
"""The history holds at most ``HISTORY_OWNERS * history`` jobs over every owner; beyond
that, the owner holding the most gives up its oldest (``docs/owners.md``)."""


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
    silence them), and the last ``history`` (>= 0) of each owner that are over (at most
    :data:`HISTORY_OWNERS` times as many in all: so one client's flood of touches never
    evicts another's job); ``handles``: the same by their integer on the audio side."""

    def __init__(self, history: int = HISTORY_JOBS) -> None:
        self.history = history
        self._live: dict[str, JobRecord] = {}
        self._stopping: dict[str, JobRecord] = {}
        self._over: dict[str | None, OrderedDict[str, JobRecord]] = {}
        self._over_owner: dict[str, str | None] = {}
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
        found = self._live.get(job_id) or self._stopping.get(job_id)
        if found is None and job_id in self._over_owner:
            found = self._over[self._over_owner[job_id]].get(job_id)
        return found

    def live_of(self, owner: str) -> list[JobRecord]:
        """The jobs of ``owner`` scheduled or playing, oldest first."""
        return [record for record in self._live.values() if record.owner == owner]

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
        """Move a job that is over into its owner's bounded history: past ``history`` jobs
        the owner's oldest goes; past ``HISTORY_OWNERS * history`` in all, that of the owner
        holding the most (a flood evicts its own jobs first)."""
        record.plan = None
        self._live.pop(record.job_id, None)
        self._stopping.pop(record.job_id, None)
        mine = self._over.setdefault(record.owner, OrderedDict())
        mine[record.job_id] = record
        self._over_owner[record.job_id] = record.owner
        if len(mine) > self.history:
            self._forget_oldest(record.owner)
        if len(self._over_owner) > HISTORY_OWNERS * self.history:
            self._forget_oldest(max(self._over, key=lambda o: len(self._over[o])))

    def _forget_oldest(self, owner: str | None) -> None:
        held = self._over[owner]
        if held:
            job_id, old = held.popitem(last=False)
            self._over_owner.pop(job_id, None)
            self.handles.pop(old.handle, None)
        if not held:
            del self._over[owner]


def _fair_victims(
    sounding: list[JobRecord], start_frame: int, owner: str | None, policy: Policy
) -> Iterator[JobRecord]:
    """Jobs to steal, in turn, by the fair-share rule (:mod:`~phantomtouch.engine.shares`,
    ``docs/owners.md``): from the owners it lets yield to ``owner``, the one whose next
    candidate comes first in the policy's order; when none yields, ``owner``'s own (its
    new touch replaces its oldest); none under ``refuse``."""
    if policy == "refuse":
        return
    held = Counter(record.owner for record in sounding)
    order = _STEAL_ORDER[policy]
    candidates: dict[str | None, list[JobRecord]] = {}
    for record in sorted(sounding, key=order, reverse=True):
        if record.first_frame <= start_frame and record.state != "stopped":
            candidates.setdefault(record.owner, []).append(record)
    while True:
        givers = yielding(held, owner) or ([owner] if held[owner] else [])
        ready = [o for o in givers if candidates.get(o)]
        if not ready:
            return
        holder = min(ready, key=lambda o: order(candidates[o][-1]))
        held[holder] -= 1
        yield candidates[holder].pop()


def _fits(load: float, count: int, budget: float, voices: int) -> bool:
    """Within ``voices``, and within the ``budget`` (one voice alone always fits it)."""
    return count <= voices and (count <= 1 or load <= budget * (1.0 + 1e-9))
