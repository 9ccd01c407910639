"""What the audio callback reports, turned into job states and stimulus-log records.

The callback appends events to a deque (see :mod:`phantomtouch.engine.scheduler`); the
:class:`Reporter` drains it under the engine's lock — on every query and every 50 ms from
its housekeeping thread, which also writes the stimulus log and reports callback errors.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.contacts import ContactVoice
from phantomtouch.engine.jobs import JobTable
from phantomtouch.engine.log import StimulusLog
from phantomtouch.engine.scheduler import Scheduler
from phantomtouch.engine.voices import PatternVoice

logger = logging.getLogger("phantomtouch.engine")

HOUSEKEEPING_PERIOD_S = 0.05
LOG_PATTERN_MAX_POINTS = 1000
"""Patterns with longer paths are logged by their summary alone."""


class Reporter:
    """Drains the callback's events into the job table and the stimulus log.

    Parameters
    ----------
    scheduler : Scheduler
    clock : SampleClock
        Maps event frames to server and wall-clock time for the log.
    jobs : JobTable
    log : StimulusLog or None
    lock : threading.RLock
        The engine's lock; :meth:`drain` expects it held.
    """

    def __init__(
        self,
        scheduler: Scheduler,
        clock: SampleClock,
        jobs: JobTable,
        log: StimulusLog | None,
        lock: threading.RLock,
    ) -> None:
        self._scheduler = scheduler
        self._clock = clock
        self._jobs = jobs
        self._log = log
        self._lock = lock
        self._backlog: list[dict[str, Any]] = []
        self._reported_error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._halt = threading.Event()

    def start(self) -> None:
        """Start the housekeeping thread."""
        self._halt.clear()
        self._thread = threading.Thread(
            target=self._run, name="phantomtouch-engine-housekeeping", daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        """Stop the housekeeping thread after a last flush."""
        thread, self._thread = self._thread, None
        self._halt.set()
        if thread is not None:
            thread.join()
        self.flush()

    def close(self) -> None:
        self.stop()
        if self._log is not None:
            self._log.close()

    def _run(self) -> None:
        while not self._halt.wait(HOUSEKEEPING_PERIOD_S):
            self.flush()

    def flush(self) -> None:
        """Drain events, write the log, report a new callback error."""
        with self._lock:
            self.drain()
            backlog, self._backlog = self._backlog, []
        error = self._scheduler.last_error
        if error is not None and error is not self._reported_error:
            self._reported_error = error
            logger.error("audio callback failed; voices dropped", exc_info=error)
        if self._log is not None:
            self._log.write(backlog)

    def drain(self) -> None:
        """Apply what the callback reported (the caller holds the engine's lock)."""
        events = self._scheduler.events
        while events:
            event = events.popleft()
            if event[0] == "stop_all":
                self._note({"event": "stop_all"}, event[1])
                continue
            kind, voice, frame = event[0], event[1], event[2]
            if isinstance(voice, PatternVoice):
                self._job_event(kind, voice, frame, event)
            elif isinstance(voice, ContactVoice):
                record: dict[str, Any] = {
                    "event": kind,
                    "kind": "contact",
                    "owner": voice.owner,
                    "contact": voice.contact,
                }
                if kind == "start":
                    target = voice.down_target
                    record.update(x_cm=target.x_cm, y_cm=target.y_cm, amplitude=target.amplitude)
                self._note(record, frame)

    def _job_event(self, kind: str, voice: PatternVoice, frame: int, event: tuple) -> None:
        record: dict[str, Any] = {
            "event": kind,
            "kind": "job",
            "job_id": voice.job_id,
            "owner": voice.owner,
        }
        if kind == "start" and self._log is not None:
            record.update(late=bool(event[3]), summary=voice.plan.summary())
            pattern = voice.plan.pattern
            path = pattern.path
            points = getattr(path, "points_cm", None) or getattr(path, "keyframes", None) or ()
            if len(points) <= LOG_PATTERN_MAX_POINTS:
                record["pattern"] = pattern.model_dump(mode="json")
        self._note(record, frame)
        job = self._jobs.get(voice.job_id)
        if job is None:
            return
        if kind == "start":
            job.start_frame, job.late = frame, bool(event[3])
            if job.state == "scheduled":
                job.state = "playing"
        elif kind == "release":
            job.end_frame = voice.silent_from
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
        server_time_s = self._clock.time_at(frame)
        record.update(
            frame=frame,
            server_time_s=server_time_s,
            unix_time_s=server_time_s + (time.time() - time.monotonic()),
        )
        self._backlog.append(record)
