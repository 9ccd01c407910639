"""Jobs: scheduled patterns as the control side sees them.

A job is ``scheduled`` until its first frame is played, ``playing`` until its last, then
``finished`` — or ``stopped`` once a stop was asked for (it then fades out over the
release). The table keeps every job that is not over and the most recent ones that are.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from phantomtouch.engine.voices import PatternVoice
from phantomtouch.errors import EngineBusyError, ParameterError
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

JobStateName = Literal["scheduled", "playing", "finished", "stopped"]
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
    """

    job_id: str
    start_frame: int
    frames: int
    duration_s: float
    summary: dict[str, Any] = field(hash=False)


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

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class JobRecord:
    """The control side's mutable view of one job (under the engine's lock)."""

    voice: PatternVoice | None
    job_id: str
    owner: str | None
    requested_start_frame: int
    frames: int
    duration_s: float
    state: JobStateName = "scheduled"
    start_frame: int | None = None
    end_frame: int | None = None
    late: bool = False

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

    def overlapping(self, start_frame: int, end_frame: int) -> int:
        """Jobs not over (stopping ones included) that sound within [start, end) frames."""
        count = 0
        for table in (self._live, self._stopping):
            for record in table.values():
                first = (
                    record.requested_start_frame
                    if record.start_frame is None
                    else record.start_frame
                )
                if first < end_frame and first + record.frames > start_frame:
                    count += 1
        return count

    def check_room(self, start_frame: int, frames: int, *, jobs: int, voices: int) -> None:
        """Refuse a job when ``jobs`` are scheduled or playing already, or when it would
        sound together with ``voices`` others anywhere in its frames.

        Raises
        ------
        EngineBusyError
            Naming the limit (``queue_capacity`` or ``max_voices``) and the count.
        """
        if len(self._live) >= jobs:
            raise EngineBusyError(
                f"the engine is full: {len(self._live)} jobs are scheduled or playing; "
                f"at most queue_capacity={jobs}"
            )
        sounding = self.overlapping(start_frame, start_frame + frames)
        if sounding >= voices:
            raise EngineBusyError(
                f"{sounding} pattern voices would sound at once from frame {start_frame}; "
                f"at most max_voices={voices}"
            )

    def add(self, record: JobRecord) -> None:
        self._live[record.job_id] = record

    def get(self, job_id: str) -> JobRecord | None:
        return self._live.get(job_id) or self._stopping.get(job_id) or self._over.get(job_id)

    def mark_stopped(self, record: JobRecord) -> None:
        """The job was asked to stop; the callback will silence it."""
        record.state = "stopped"
        if self._live.pop(record.job_id, None) is not None:
            self._stopping[record.job_id] = record

    def stop_all(self) -> None:
        for record in list(self._live.values()):
            self.mark_stopped(record)

    def retire(self, record: JobRecord) -> None:
        """Move a job that is over into the bounded history."""
        record.voice = None
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
