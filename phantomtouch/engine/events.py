"""What the audio side reports, turned into job states and stimulus-log records.

The audio side reports plain events (:mod:`phantomtouch.engine.core`); the control side
hands them to :meth:`Ledger.apply` under its lock: from the in-thread engine's
housekeeping thread, or from the thread that reads the engine process's reports. The log
is written outside the lock (:meth:`Ledger.flush`), never by the audio callback.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

from phantomtouch.engine.jobs import JobTable
from phantomtouch.engine.log import StimulusLog

LOG_PATTERN_MAX_POINTS = 1000
"""Patterns with longer paths are logged by their summary alone."""


class Ledger:
    """Applies events to the job table and keeps the stimulus-log records due.

    Parameters
    ----------
    jobs : JobTable
    time_at : callable
        ``time_at(frame)``: server time, s, of a frame leaving the sound card.
    log : StimulusLog or None
    """

    def __init__(
        self, jobs: JobTable, time_at: Callable[[int], float], log: StimulusLog | None
    ) -> None:
        self._jobs = jobs
        self._time_at = time_at
        self._log = log
        self._backlog: list[dict[str, Any]] = []

    def apply(self, events: Iterable[tuple[Any, ...]]) -> None:
        """Apply events (the caller holds the engine's lock)."""
        for event in events:
            if event[0] == "stop_all":
                self._note({"event": "stop_all"}, event[1])
            elif event[1] == "job":
                self._job_event(event)
            else:
                owner, contact = event[2]
                record: dict[str, Any] = {
                    "event": event[0],
                    "kind": "contact",
                    "owner": owner,
                    "contact": contact,
                }
                if event[0] == "start":
                    record.update(x_cm=event[5], y_cm=event[6], amplitude=event[7])
                self._note(record, event[3])

    def _job_event(self, event: tuple[Any, ...]) -> None:
        kind, job_id, frame = event[0], event[2], event[3]
        job = self._jobs.get(job_id)
        record: dict[str, Any] = {
            "event": kind,
            "kind": "job",
            "job_id": job_id,
            "owner": None if job is None else job.owner,
        }
        if kind == "start" and self._log is not None and job is not None and job.plan:
            record.update(late=bool(event[4]), summary=job.plan.summary())
            pattern = job.plan.pattern
            path = pattern.path
            points = getattr(path, "points_cm", None) or getattr(path, "keyframes", None) or ()
            if len(points) <= LOG_PATTERN_MAX_POINTS:
                record["pattern"] = pattern.model_dump(mode="json")
        self._note(record, frame)
        if job is None:
            return
        if kind == "start":
            job.start_frame, job.late = frame, bool(event[4])
            if job.state == "scheduled":
                job.state = "playing"
        elif kind == "release":
            job.end_frame = event[4]
        elif kind == "end":
            job.end_frame = frame
            if job.state != "stopped":
                job.state = "finished"
            self._jobs.retire(job)
        elif kind == "cancel":
            job.state = "stopped"
            job.end_frame = job.requested_start_frame
            self._jobs.retire(job)

    def _note(self, record: dict[str, Any], frame: int) -> None:
        if self._log is None:
            return
        server_time_s = self._time_at(frame)
        record.update(
            frame=frame,
            server_time_s=server_time_s,
            unix_time_s=server_time_s + (time.time() - time.monotonic()),
        )
        self._backlog.append(record)

    def take_backlog(self) -> list[dict[str, Any]]:
        """The log records due (the caller holds the engine's lock)."""
        backlog, self._backlog = self._backlog, []
        return backlog

    def flush(self, records: list[dict[str, Any]]) -> None:
        """Write records taken with :meth:`take_backlog` (outside the lock)."""
        if self._log is not None:
            self._log.write(records)

    def close(self) -> None:
        if self._log is not None:
            self._log.close()
