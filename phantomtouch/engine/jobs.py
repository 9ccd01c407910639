"""Jobs: scheduled patterns as the control side sees them.

A job is ``scheduled`` until its first frame is played, ``playing`` until its last, then
``finished`` — or ``stopped`` once a stop was asked for (it then fades out over the
release). The table keeps every job that is not over and the most recent ones that are.
"""

from __future__ import annotations

from collections import Counter, OrderedDict
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from phantomtouch.errors import EngineBusyError, ParameterError
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

JobStateName = Literal["scheduled", "playing", "finished", "stopped"]
Policy = Literal["refuse", "steal-oldest", "steal-quietest"]
POLICIES: tuple[Policy, ...] = ("refuse", "steal-oldest", "steal-quietest")
"""What happens to a job beyond the voice budget: refused (EngineBusyError), or the
oldest or the quietest sounding job fades out to make room (as game audio engines steal
voices)."""
HISTORY_JOBS = 1000
"""Jobs that are over and still answered by :meth:`Engine.job_state`."""


@dataclass(frozen=True)
class Job:
    """A pattern accepted by :meth:`Engine.schedule`.

    Attributes
    ----------
    job_id : str
    start_frame : int
        Frame of its first sample on the engine's sample clock. For a job scheduled as
        soon as possible this is the block it is expected to start in;
        :meth:`Engine.job_state` gives the frame it actually started at.
    frames : int
        Length of the pattern, frames.
    duration_s : float
    summary : dict
        The plan's summary (``Plan.summary()``).
    start_at_s : float or None
        Server time, s, at which ``start_frame`` leaves the sound card, fixed when the job
        was scheduled (:attr:`JobState.requested_start_at_s` answers the same value).
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
    job_id : str
    state : {"scheduled", "playing", "finished", "stopped"}
    owner : str or None
    start_frame : int
        Actual first frame once it started; the requested one before.
    end_frame : int
        Frame from which it is silent: ``start_frame + frames`` unless stopped, then the
        end of its release (``start_frame`` when stopped before it started).
    frames : int
    duration_s : float
    requested_start_frame : int
    late : bool
        It started after its requested frame (its command arrived too late).
    requested_start_at_s : float or None
        Server time, s, of ``requested_start_frame`` as :attr:`Job.start_at_s` gave it
        (the clock's mapping of frames to time moves a little as it tracks the card).
    reason : str or None
        Why a ``stopped`` job stopped when no one asked it to: ``stolen`` (faded out to
        make room for another), or the engine's fault (``engine gone before it played``,
        ``engine stalled while it played``); None otherwise.
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
    """The control side's mutable view of one job (under the engine's lock).

    ``plan`` is dropped once the job is over; a ``stolen`` job was faded out to make
    room for another and no longer counts against the voice budget.
    """

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

    @property
    def first_frame(self) -> int:
        return self.requested_start_frame if self.start_frame is None else self.start_frame

    def snapshot(self) -> JobState:
        start = self.requested_start_frame if self.start_frame is None else self.start_frame
        end = start + self.frames if self.end_frame is None else self.end_frame
        return JobState(
            job_id=self.job_id,
            state=self.state,
            owner=self.owner,
            start_frame=start,
            end_frame=end,
            frames=self.frames,
            duration_s=self.duration_s,
            requested_start_frame=self.requested_start_frame,
            late=self.late,
            requested_start_at_s=self.requested_start_at_s,
            reason="stolen" if self.stolen and self.reason is None else self.reason,
        )


class JobTable:
    """Jobs by id: those not over yet, and the last ``history`` that are.

    A job that was asked to stop no longer counts as live, though the callback has yet to
    silence it.

    Parameters
    ----------
    history : int, >= 0
    """

    def __init__(self, history: int = HISTORY_JOBS) -> None:
        self.history = history
        self._live: dict[str, JobRecord] = {}
        self._stopping: dict[str, JobRecord] = {}
        self._over: OrderedDict[str, JobRecord] = OrderedDict()

    def __len__(self) -> int:
        """Jobs scheduled or playing (not stopping, not over)."""
        return len(self._live)

    def _sounding(self, start_frame: int, end_frame: int) -> list[JobRecord]:
        """Jobs not over and not stolen that sound within [start, end) frames."""
        found = []
        for table in (self._live, self._stopping):
            for record in table.values():
                first = record.first_frame
                last = first + record.frames if record.end_frame is None else record.end_frame
                if not record.stolen and first < end_frame and last > start_frame:
                    found.append(record)
        return found

    def overlapping(self, start_frame: int, end_frame: int) -> int:
        """Jobs not over (stopping ones included, stolen ones not) within [start, end)."""
        return len(self._sounding(start_frame, end_frame))

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
        """Make room for a job of ``owner`` of ``frames`` from ``start_frame`` costing
        ``cost``, or refuse.

        Refused when ``jobs`` are scheduled or playing already. When, together with the
        jobs sounding at the same time, it would exceed the render ``budget`` (the sum of
        their costs, shares of a block) or ``voices`` voices, ``policy`` decides:
        ``refuse``, or the jobs to steal, as few as make room, are returned; the caller
        fades them out. Each is taken from whoever holds the most voices then (max-min
        fairness, the new job counted for its owner; on a tie the new job's owner first),
        and among that owner's jobs sounding at the start, the oldest started or the
        quietest. An owner holding fewer voices than another is never stolen from: if
        the largest holder has nothing to steal at the start, the job is refused.

        Raises
        ------
        EngineBusyError
            Naming the limit (``queue_capacity``, or the voice budget) and the count.
        """
        if len(self._live) >= jobs:
            raise EngineBusyError(
                f"the engine is full: {len(self._live)} jobs are scheduled or playing; "
                f"at most queue_capacity={jobs}"
            )
        sounding = self._sounding(start_frame, start_frame + frames)
        load = cost + sum(record.cost for record in sounding)
        count = len(sounding) + 1
        if _fits(load, count, budget, voices):
            return []
        victims: list[JobRecord] = []
        if policy != "refuse":
            for record in _fair_victims(sounding, start_frame, owner, policy):
                victims.append(record)
                load -= record.cost
                count -= 1
                if _fits(load, count, budget, voices):
                    return victims
        capacity = voices if cost <= 0.0 else min(voices, int(budget / cost + 1e-9))
        raise EngineBusyError(
            f"{len(sounding)} pattern voices would sound at once from frame {start_frame}; "
            f"the voice budget allows {max(1, capacity)} such voices ({budget:.0%} of a "
            f"block's time, at most {voices}; voice policy {policy!r})"
        )

    def add(self, record: JobRecord) -> None:
        self._live[record.job_id] = record

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

    def drop_all(self, frame: int, *, fault: str = "gone") -> None:
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
            self._over.popitem(last=False)


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
    """Jobs to steal, in turn, each from the largest holder of the voices left (see
    :meth:`JobTable.admit`); ends when the largest holder has nothing to steal."""
    held = Counter(record.owner for record in sounding)
    held[owner] += 1
    candidates: dict[str | None, list[JobRecord]] = {}
    for record in sounding:
        if record.first_frame <= start_frame and record.state != "stopped":
            candidates.setdefault(record.owner, []).append(record)
    for group in candidates.values():
        group.sort(key=_age if policy == "steal-oldest" else _quiet, reverse=True)
    while True:
        most = max(held.values())
        largest = [o for o, n in held.items() if n == most]
        holder = owner
        if owner not in largest:
            ready = [o for o in largest if candidates.get(o)]
            if not ready:
                return  # the largest holders have nothing to steal; the others hold less
            order = _age if policy == "steal-oldest" else _quiet
            holder = min(ready, key=lambda o: order(candidates[o][-1]))
        taken = candidates.get(holder)
        if not taken:
            return
        record = taken.pop()
        held[holder] -= 1
        yield record


def _age(record: JobRecord) -> tuple[int, str]:
    return record.first_frame, record.job_id


def _quiet(record: JobRecord) -> tuple[float, int]:
    return record.amplitude, record.first_frame


def _fits(load: float, count: int, budget: float, voices: int) -> bool:
    """Within ``voices``, and within the ``budget`` (one voice alone always fits it)."""
    return count <= voices and (count <= 1 or load <= budget * (1.0 + 1e-9))
