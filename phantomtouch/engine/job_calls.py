"""The front's job calls: schedule, stop and look up jobs over the one
:class:`~phantomtouch.engine.jobs.JobTable`, with admission and fair stealing
(``docs/engine.md``, ``docs/owners.md``)."""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

from phantomtouch.engine.checks import check_ahead, check_frame, check_id
from phantomtouch.engine.jobs import (
    POLICIES,
    Job,
    JobRecord,
    JobState,
    JobStateName,
    JobTable,
    OwnerQuota,
    Policy,
)
from phantomtouch.engine.messages import DropPlan, HoldPlan, ReleaseJob, StartJob
from phantomtouch.engine.owners import post_release
from phantomtouch.engine.render_budget import Admission
from phantomtouch.errors import ParameterError
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

if TYPE_CHECKING:
    from phantomtouch.engine.job_ids import JobIds
    from phantomtouch.engine.local_audio import LocalAudio
    from phantomtouch.engine.plans import HeldPlan, PlanCache
    from phantomtouch.engine.process import ChildAudio

MAX_SCHEDULE_AHEAD_S = 3600.0
"""Latest start a job may ask for, s after the current frame."""
PREPARE_BLOCKS = 1
"""Blocks after the next that a job asked for as soon as possible and not prerendered is
promised: its voice is prepared outside the callback meanwhile (``docs/engine.md``)."""


class JobCalls:
    """The job methods of :class:`~phantomtouch.engine.front.EngineFront`, which makes
    the state below; every method runs in the host, on any thread."""

    plans: PlanCache
    device: DeviceProfile
    _lock: threading.RLock
    _audio: LocalAudio | ChildAudio
    _jobs: JobTable
    _job_ids: JobIds
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
        job_id = self._job_ids.next()
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

    def check_quota(self, owner: str, quota: OwnerQuota, least_s: float = 0.0) -> None:
        """Raise :class:`QuotaRefused` if ``owner`` has no room left for a job of at least
        ``least_s`` s (>= 0): its jobs not over already number ``quota.voices``, or hold
        so much of ``quota.seconds`` that ``least_s`` more would pass it (host, any
        thread). Cheap: a caller checks it before it plans a pattern, with what the
        pattern says of its length before planning, so a refused touch costs no planning
        (:meth:`schedule` checks the job itself once it is planned)."""
        check_id("owner", owner)
        rate_hz = self.device.sample_rate_hz
        frames = round(max(0.0, float(least_s)) * rate_hz)
        with self._lock:
            next_frame = self._audio.next_block_frame()
            self._jobs.check_quota(
                owner, quota, next_frame, frames, next_frame=next_frame, rate_hz=rate_hz
            )

    async def schedule_async(self, pattern: TouchPattern | Plan, **options: Any) -> Job:
        """:meth:`schedule` for a coroutine, with its keywords (host, the event loop; it
        never waits for the audio side)."""
        return self.schedule(pattern, **options)

    def job_state(self, job_id: str) -> JobState | None:
        """The state of a job, or None if unknown (or too old: the last 1000 of its owner
        are kept, :class:`~phantomtouch.engine.jobs.JobTable`); host, any thread."""
        self._audio.sync()
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            return None if record is None else record.snapshot()

    def job_states(self, job_ids: Sequence[str]) -> list[JobStateName | None]:
        """The state name of each of ``job_ids`` (None: unknown, or forgotten with its
        owner's history), in one hold of the lock, one look-up per id (host, any thread).
        Unlike :meth:`job_state` it does not wait for the audio side's newest reports: a job
        whose end is not yet reported reads ``playing`` a housekeeping tick longer."""
        with self._lock:
            found = [self._jobs.get(job_id) for job_id in job_ids]
            return [None if record is None else record.state for record in found]

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

    def live_jobs(self, owner: str) -> int:
        """How many jobs of ``owner`` are scheduled or playing (host, any thread)."""
        with self._lock:
            return len(self._jobs.live_of(owner))

    def stop_owner(self, owner: str, reason: str = "closed") -> int:
        """Stop every job of ``owner`` scheduled or playing, each with its release ramp
        (its state says ``stopped`` with ``reason``: the owner went, ``docs/owners.md``);
        host, any thread. Returns how many were stopped; never refused."""
        with self._lock:
            records = self._jobs.live_of(owner)
            for record in records:
                post_release(self._audio, ReleaseJob(record.handle, None, None))
                self._jobs.mark_stopped(record)
                record.reason = reason
            return len(records)
