"""What the audio side reports, turned into job states and stimulus-log records.

The front hands events to :meth:`Reports.apply` under its lock; the log is written
outside it (:meth:`Reports.flush`), never by the audio callback.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

from phantomtouch.engine.jobs import JobTable
from phantomtouch.engine.log import StimulusLog
from phantomtouch.engine.messages import (
    Cancelled,
    Ended,
    Event,
    Released,
    Started,
    StoppedAll,
    VoiceEvent,
)

LOG_PATTERN_MAX_POINTS = 1000
"""Patterns with longer paths are logged by their summary alone."""
_NAMES: dict[type, str] = {Started: "start", Released: "release", Ended: "end", Cancelled: "cancel"}
"""The stimulus log's name of each event."""


class Reports:
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

    def apply(self, events: Iterable[Event]) -> None:
        """Apply events (host, the caller holds the front's lock); events about anything
        but voices (a noise loop released, a refusal) are not the ledger's and pass."""
        for event in events:
            if isinstance(event, StoppedAll):
                self._note({"event": "stop_all"}, event.frame)
            elif isinstance(event, VoiceEvent):
                self._voice_event(event)

    def _voice_event(self, event: VoiceEvent) -> None:
        record: dict[str, Any] = {"event": _NAMES[type(event)], "kind": event.kind}
        if event.kind != "job":
            record["owner"], record["contact"] = event.key
            if isinstance(event, Started):
                record.update(x_cm=event.x_cm, y_cm=event.y_cm, amplitude=event.amplitude)
            self._note(record, event.frame)
            return
        job_id, frame = event.key, event.frame
        job = self._jobs.get(job_id)
        record.update(job_id=job_id, owner=None if job is None else job.owner)
        if isinstance(event, Started) and self._log is not None and job is not None and job.plan:
            record.update(late=event.late, summary=job.plan.summary())
            pattern = job.plan.pattern
            path = pattern.path
            points = getattr(path, "points_cm", None) or getattr(path, "keyframes", None) or ()
            if len(points) <= LOG_PATTERN_MAX_POINTS:
                record["pattern"] = pattern.model_dump(mode="json")
        self._note(record, frame)
        if job is None:
            return
        if isinstance(event, Started):
            job.start_frame, job.late = frame, event.late
            if job.state == "scheduled":
                job.state = "playing"
        elif isinstance(event, Released):
            job.end_frame = event.silent_from
        elif isinstance(event, Ended):
            job.end_frame = frame
            if job.state != "stopped":
                job.state = "finished"
            self._jobs.retire(job)
        else:  # cancelled
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
        """The log records due (host; the caller holds the front's lock)."""
        backlog, self._backlog = self._backlog, []
        return backlog

    def flush(self, records: list[dict[str, Any]]) -> None:
        """Write records taken with :meth:`take_backlog` (host, outside the lock)."""
        if self._log is not None:
            self._log.write(records)

    def close(self) -> None:
        """Close the log (host)."""
        if self._log is not None:
            self._log.close()
