"""What the audio side reports, turned into job states and stimulus-log records.

The front applies events under its lock; the log is written outside it, never by the
audio callback.
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
    """Applies events to the job table and writes the stimulus log.

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

    def apply(self, events: Iterable[Event]) -> list[dict[str, Any]]:
        """Apply events and return the log records due (host, under the front's lock);
        events about anything but voices (a noise loop released, a refusal) pass."""
        records: list[dict[str, Any]] = []
        for event in events:
            if isinstance(event, VoiceEvent):
                record = self._voice_event(event)
            elif isinstance(event, StoppedAll):
                record = {"event": "stop_all"}
            else:
                continue
            if self._log is not None:
                time_s = self._time_at(event.frame)
                unix_s = time_s + (time.time() - time.monotonic())
                record.update(frame=event.frame, server_time_s=time_s, unix_time_s=unix_s)
                records.append(record)
        return records

    def _voice_event(self, event: VoiceEvent) -> dict[str, Any]:
        record: dict[str, Any] = {"event": _NAMES[type(event)], "kind": event.kind}
        if event.kind != "job":
            record["owner"], record["contact"] = event.key
            if isinstance(event, Started):
                record.update(x_cm=event.x_cm, y_cm=event.y_cm, amplitude=event.amplitude)
            return record
        job = self._jobs.get(event.key)
        record.update(job_id=event.key, owner=None if job is None else job.owner)
        if job is None:
            return record
        if isinstance(event, Started):
            if self._log is not None and job.plan:
                record.update(late=event.late, summary=job.plan.summary())
                path = job.plan.pattern.path
                points = getattr(path, "points_cm", None) or getattr(path, "keyframes", None)
                if len(points or ()) <= LOG_PATTERN_MAX_POINTS:
                    record["pattern"] = job.plan.pattern.model_dump(mode="json")
            job.start_frame, job.late = event.frame, event.late
            if job.state == "scheduled":
                job.state = "playing"
        elif isinstance(event, Released):
            job.end_frame = event.silent_from
        elif isinstance(event, Ended):
            job.end_frame = event.frame
            if job.state != "stopped":
                job.state = "finished"
            self._jobs.retire(job)
        else:  # cancelled
            job.state = "stopped"
            job.end_frame = job.requested_start_frame
            self._jobs.retire(job)
        return record

    def write(self, records: list[dict[str, Any]]) -> None:
        """Write the records :meth:`apply` returned (host, outside the front's lock)."""
        if self._log is not None:
            self._log.write(records)

    def close(self) -> None:
        """Close the log (host)."""
        if self._log is not None:
            self._log.close()
