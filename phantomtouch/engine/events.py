"""What the audio side reports, applied to the job table and made stimulus-log records."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from phantomtouch.engine.jobs import JobTable
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


def apply_events(
    jobs: JobTable,
    names: Mapping[int, tuple[str, str]],
    events: Iterable[Event],
    time_at: Callable[[int], float] | None,
) -> list[dict[str, Any]]:
    """Apply the audio side's events to ``jobs`` (host, under the front's lock) and
    return their stimulus-log records, to be written outside it; ``jobs`` and ``names`` (a
    contact's ``(owner, contact)``) map an event's integer back to its job or contact.

    ``time_at(frame)`` is the server time, s, of a frame leaving the sound card (None: no
    log is kept, no records are made). Events about anything but voices (a noise loop
    released, a refusal) pass.
    """
    records: list[dict[str, Any]] = []
    for event in events:
        if isinstance(event, VoiceEvent):
            record = _voice_event(jobs, names, event, time_at is not None)
        elif isinstance(event, StoppedAll):
            record = {"event": "stop_all"}
        else:
            continue
        if time_at is not None:
            time_s = time_at(event.frame)
            unix_s = time_s + (time.time() - time.monotonic())
            record.update(frame=event.frame, server_time_s=time_s, unix_time_s=unix_s)
            records.append(record)
    return records


def _voice_event(
    jobs: JobTable, names: Mapping[int, tuple[str, str]], event: VoiceEvent, logged: bool
) -> dict[str, Any]:
    """Apply one voice's event to its job, if any; its log record (fuller when ``logged``)."""
    record: dict[str, Any] = {"event": _NAMES[type(event)], "kind": event.kind}
    if event.kind != "job":
        record["owner"], record["contact"] = names.get(event.key, (None, None))
        if isinstance(event, Started):
            record.update(x_cm=event.x_cm, y_cm=event.y_cm, amplitude=event.amplitude)
        return record
    job = jobs.handles.get(event.key)
    record.update(job_id=job and job.job_id, owner=job and job.owner)
    if job is None:
        return record
    if isinstance(event, Started):
        if logged and job.plan:
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
    else:  # ended, or cancelled before it started
        ended = isinstance(event, Ended)
        job.state = "finished" if ended and job.state != "stopped" else "stopped"
        job.end_frame = event.frame if ended else job.requested_start_frame
        jobs.retire(job)
    return record
