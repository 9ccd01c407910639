"""The real-time engine: patterns and live contacts played on the armband's sound card.

Every public method may be called from any thread: it builds small commands under the
engine's lock (never taken by the audio callback) and pushes them into a bounded queue
that the callback drains at the start of each block (:mod:`phantomtouch.engine.scheduler`).
A housekeeping thread collects what the callback reports (job states, the stimulus log)
every 50 ms; the query methods collect it too. See the README for an example.
"""

from __future__ import annotations

import threading
import time
import uuid
from pathlib import Path

from phantomtouch.engine.board import ContactBoard
from phantomtouch.engine.checks import check_ahead, check_frame, check_id, check_int, check_seconds
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.commands import CommandQueue
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.events import Reporter
from phantomtouch.engine.jobs import Job, JobRecord, JobState, JobTable, resolve_plan
from phantomtouch.engine.log import StimulusLog
from phantomtouch.engine.scheduler import Scheduler
from phantomtouch.engine.shared import MoveSlots
from phantomtouch.engine.sinks import NullSink, Sink
from phantomtouch.engine.status import EngineFront, EngineStatus
from phantomtouch.engine.voices import PatternVoice
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Carrier, TouchPattern

MAX_SCHEDULE_AHEAD_S = 3600.0
"""Latest start a job may ask for, s after the current frame."""
MAX_QUEUE_CAPACITY = 1_000_000
MAX_VOICES = 64
"""Default of ``max_voices``: pattern voices that may sound at once. On a 2-core machine
64 of the paper's 12 s stimuli take a fifth of a 256-frame block at p99
(``benchmarks/bench_engine.py``), leaving room for contacts, smaller blocks and the
host's own work; ``benchmarks/bench_server.py`` overloads the cap with taps."""
RENDER_AHEAD_FRAMES = 4096
"""Frames a pattern voice renders ahead at a time (see :mod:`phantomtouch.engine.voices`)."""
RENDER_AHEAD_RINGS = 64
"""Most pattern voices that render ahead at once: the engine preallocates a ring (two
chunks, 256 KB at 8 channels) for each of ``min(max_voices, RENDER_AHEAD_RINGS)``
voices; voices beyond render block by block."""


class Engine(EngineFront):
    """Plays scheduled patterns and live contacts through a sink, sample-accurately.

    Parameters
    ----------
    device : DeviceProfile
        Layout, sample rate, block size, calibration and safety limits.
    sink : Sink or None
        Where the blocks go; the engine owns it from now on and closes it. None: a
        :class:`~phantomtouch.engine.sinks.NullSink` (use
        :func:`~phantomtouch.engine.soundcard.open_default_sink` for the sound card).
    queue_capacity : int, 1 <= queue_capacity <= 1_000_000
        Most jobs and touchdowns waiting to start, and most jobs scheduled or playing at
        once; more raise EngineBusyError.
    max_voices : int, 1 <= max_voices <= 1_000_000
        Most pattern voices that may sound at the same time: a job whose frames would
        overlap ``max_voices`` others is refused with EngineBusyError, so the audio
        thread is never handed more than it can render. Jobs scheduled for later count
        only where they overlap. The default, 64, renders in a fifth of real time on a
        2-core machine (``MAX_VOICES``); raise it on a faster one.
    contact : ContactSettings or None
        Attack, release and transients of contacts (and the release of stopped jobs).
    log_path : str, Path or None
        Append the stimulus log (JSON lines, :mod:`phantomtouch.engine.log`) here.
    render_ahead_frames : int, >= 0
        Frames a pattern voice renders ahead at a time; 0 renders every block directly.
    clock : SampleClock or None
        The sample clock to keep, at the device's sample rate (one that publishes itself
        to another process, say); None: a new one.

    Raises
    ------
    ParameterError
        An argument is out of range.
    DeviceError
        The sink's sample rate, block size or channels differ from the device's.
    """

    def __init__(
        self,
        device: DeviceProfile,
        sink: Sink | None = None,
        *,
        queue_capacity: int = 4096,
        max_voices: int = MAX_VOICES,
        contact: ContactSettings | None = None,
        log_path: str | Path | None = None,
        render_ahead_frames: int = RENDER_AHEAD_FRAMES,
        clock: SampleClock | None = None,
    ) -> None:
        if not isinstance(device, DeviceProfile):
            raise ParameterError(f"device={device!r} must be a DeviceProfile")
        check_int("queue_capacity", queue_capacity, 1, MAX_QUEUE_CAPACITY)
        check_int("max_voices", max_voices, 1, MAX_QUEUE_CAPACITY)
        self._max_voices = max_voices
        check_int("render_ahead_frames", render_ahead_frames, 0, 1 << 20)
        if contact is not None and not isinstance(contact, ContactSettings):
            raise ParameterError(f"contact={contact!r} must be ContactSettings or None")
        self._device = device
        self._sink: Sink = sink if sink is not None else NullSink(device)
        for name in ("sample_rate_hz", "block_frames", "channels"):
            if getattr(self._sink, name) != getattr(device, name):
                raise DeviceError(
                    f"sink {name}={getattr(self._sink, name)} differs from the device's "
                    f"{getattr(device, name)}"
                )
        self._settings = contact or ContactSettings()
        self._queue = CommandQueue(queue_capacity)
        self._board = ContactBoard(device, self._settings, self._queue)
        if clock is not None and (
            not isinstance(clock, SampleClock) or clock.sample_rate_hz != device.sample_rate_hz
        ):
            raise ParameterError(
                f"clock={clock!r} must be a SampleClock at {device.sample_rate_hz} Hz or None"
            )
        self._clock = clock if clock is not None else SampleClock(device.sample_rate_hz)
        self._scheduler = Scheduler(
            device,
            self._queue,
            self._clock,
            rings=min(max_voices, RENDER_AHEAD_RINGS),
            chunk_frames=render_ahead_frames,
            clocked=self._sink.realtime,
        )
        self._lock = threading.RLock()
        self._jobs = JobTable()
        log = StimulusLog(log_path) if log_path is not None else None
        self._reporter = Reporter(self._scheduler, self._clock, self._jobs, log, self._lock)
        self._running = False
        self._closed = False

    # -- life cycle -------------------------------------------------------------------

    def start(self) -> None:
        """Start the sink and the housekeeping thread (no-op when running).

        Raises
        ------
        DeviceError
            The engine is closed, or the sink cannot start.
        """
        with self._lock:
            self._check_open()
            if self._running:
                return
            self._clock.restart(self._scheduler.frames, time.monotonic())
            self._reporter.start()
            try:
                self._sink.start(self._scheduler.render)
            except BaseException:
                self._reporter.stop()
                raise
            self._clock.output_latency_s = max(0.0, float(self._sink.output_latency_s))
            self._running = True

    def close(self) -> None:
        """Fade everything out, stop and close the sink, flush the log. Idempotent.

        With a real-time sink and voices sounding, everything is released first and
        the release (``contact.release_s``) is played out before the output stops.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
            running, self._running = self._running, False
        try:
            if running and self._sink.realtime:
                self._fade_out()
            self._sink.close()
        finally:
            self._reporter.close()

    def _fade_out(self) -> None:
        self.stop_all()
        block_s = self.block_frames / self.sample_rate_hz
        deadline = time.monotonic() + self._settings.release_s + 4 * block_s + 0.05
        while self._scheduler.active_voices and time.monotonic() < deadline:
            time.sleep(block_s)
        time.sleep(2 * block_s)  # let the last (silent) block reach the output

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceError("the engine is closed")

    # -- clock ------------------------------------------------------------------------

    @property
    def sink(self) -> Sink:
        """The sink the engine plays into (owned by the engine)."""
        return self._sink

    @property
    def now_frames(self) -> int:
        """The sample clock: frames handed to the sink so far."""
        return self._scheduler.frames

    def server_time_s(self) -> float:
        """The server clock, s (``time.monotonic()``)."""
        return time.monotonic()

    def frames_at(self, server_time_s: float) -> int:
        """The frame that leaves the sound card at ``server_time_s`` (server clock)."""
        return self._clock.frames_at(check_seconds("server_time_s", server_time_s))

    def time_at(self, frame: int) -> float:
        """Server time, s, at which ``frame`` leaves the sound card."""
        return self._clock.time_at(check_int("frame", frame, -(1 << 62), 1 << 62))

    # -- jobs -------------------------------------------------------------------------

    def schedule(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
    ) -> Job:
        """Play a pattern from ``start_frame`` on, sample-exact.

        Parameters
        ----------
        pattern : TouchPattern or Plan
            A plan must be made for this engine's device.
        start_frame : int or None
            Frame of the pattern's first sample, at most ``MAX_SCHEDULE_AHEAD_S`` ahead;
            a frame that has passed when the command arrives starts at once (counted in
            ``late_commands``). None: as soon as possible, at the next block.
        owner : str or None
            The client it belongs to (1-64 characters), for the log and job states.

        Returns
        -------
        Job

        Raises
        ------
        ParameterError
            The pattern cannot be planned, or an argument is out of range.
        EngineBusyError
            ``queue_capacity`` jobs and touchdowns are already waiting, or
            ``queue_capacity`` jobs are scheduled or playing.
        DeviceError
            The engine is closed.
        """
        self._check_open()
        resolved = resolve_plan(pattern, self._device)
        frame = check_frame("start_frame", start_frame)
        if owner is not None:
            check_id("owner", owner)
        if frame is not None:
            check_ahead(frame, self.now_frames, self.sample_rate_hz, MAX_SCHEDULE_AHEAD_S)
        voice = PatternVoice(
            resolved,
            job_id=uuid.uuid4().hex,
            owner=owner,
            release_frames=self._board.release_frames,
        )
        with self._lock:
            self._check_open()
            self._reporter.drain()
            first = self._scheduler.next_block_frame() if frame is None else frame
            self._jobs.check_room(
                first, resolved.frames, jobs=self._queue.capacity, voices=self._max_voices
            )
            self._queue.push_start(voice, first, frame is None)
            self._jobs.add(
                JobRecord(
                    voice=voice,
                    job_id=voice.job_id,
                    owner=owner,
                    requested_start_frame=first,
                    frames=resolved.frames,
                    duration_s=resolved.duration_s,
                )
            )
        return Job(
            job_id=voice.job_id,
            start_frame=first,
            frames=resolved.frames,
            duration_s=resolved.duration_s,
            summary=resolved.summary(),
        )

    def job_state(self, job_id: str) -> JobState | None:
        """The state of a job, or None if unknown (or too old: the last 1000 are kept)."""
        with self._lock:
            self._reporter.drain()
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            return None if record is None else record.snapshot()

    def stop(self, job_id: str) -> bool:
        """Stop a job: it fades out over ``contact.release_s`` (or never starts).

        Returns
        -------
        bool
            False if the job is unknown or already over (finished or stopped).
        """
        with self._lock:
            self._reporter.drain()
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            if record is None or record.voice is None or record.state in ("finished", "stopped"):
                return False
            self._queue.push_release(record.voice, None)
            self._jobs.mark_stopped(record)
            return True

    def stop_all(self) -> None:
        """Everything off: every job and every contact of every client fades out.

        Never refused, never raises EngineBusyError: it does not queue behind other
        commands. Jobs and touchdowns accepted before this call never start.
        """
        with self._lock:
            self._queue.mark_stop_all()
            self._board.forget_all()
            self._jobs.stop_all()

    # -- contacts ---------------------------------------------------------------------

    def contact_down(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        carrier: Carrier | None = None,
        law: str = "power",
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """A contact touches down at (x_cm, y_cm) and vibrates there until ``up``.

        Parameters
        ----------
        owner : str, 1-64 characters
            The client (connection) the contact belongs to.
        contact : str, 1-64 characters
            The client's id for the contact. A contact that is already down is replaced
            (the old one fades out, the new one fades in).
        x_cm, y_cm : float, finite, |value| <= 1000
            Position; outside the layout it is projected onto it.
        intensity : float or None, 0 <= intensity <= 1
            Relative amplitude, 1 = the device's ``safety.max_level_db`` (as
            ``TouchPattern.intensity``). None: the paper's Table I "low" level for the
            carrier.
        carrier : SineCarrier, NoiseCarrier, CombinedCarrier or None
            None: a 100 Hz sine.
        law : {"power", "linear", "log"}
        normal_velocity_m_s : float or None, |value| <= 10
            Speed of the hand towards the skin: adds an impact transient scaled by it
            (see :mod:`phantomtouch.engine.contacts`). None: no transient.
        at_frame : int or None
            Frame of touchdown; None: the next block.

        Raises
        ------
        ParameterError
            An argument is out of range (the message names it).
        EngineBusyError
            The queue is full, or ``contact.max_contacts`` contacts are down.
        DeviceError
            The engine is closed.
        """
        self._check_open()
        voice = self._board.prepare_down(
            owner,
            contact,
            x_cm,
            y_cm,
            intensity=intensity,
            carrier=carrier,
            law=law,
            normal_velocity_m_s=normal_velocity_m_s,
            at_frame=at_frame,
        )
        with self._lock:
            self._check_open()
            frame = voice.down_target.frame
            first = self._scheduler.next_block_frame() if frame is None else frame
            self._board.down(voice, first, frame is None)

    def contact_move(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """The contact's newest position (and intensity); latest wins, nothing queues.

        The gains ramp from where the last block ended to this position across the
        block that contains ``at_frame`` (None: the next block).

        Raises
        ------
        ParameterError
            An argument is out of range.
        ProtocolError
            The contact is not down.
        """
        with self._lock:
            self._board.move(owner, contact, x_cm, y_cm, intensity=intensity, at_frame=at_frame)

    def contact_up(
        self,
        owner: str,
        contact: str,
        *,
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """Lift-off: the contact fades out over ``contact.release_s``.

        A contact that is not down is ignored (``up`` is idempotent). With
        ``normal_velocity_m_s``, a lift-off transient is added at the last position.
        Never refused when the queue is full.

        Raises
        ------
        ParameterError
            An argument is out of range (ids, ``normal_velocity_m_s``, ``at_frame``).
        """
        with self._lock:
            self._board.up(
                owner, contact, normal_velocity_m_s=normal_velocity_m_s, at_frame=at_frame
            )

    def release_owner(self, owner: str) -> None:
        """Release every contact of a client that went away (with the release ramp).

        Never refused; unknown owners are ignored.
        """
        with self._lock:
            self._board.release_owner(owner)

    def take_positions(self, slots: MoveSlots) -> None:
        """Apply, at the start of every block, the positions written into ``slots``.

        For :class:`~phantomtouch.engine.process.ProcessEngine`, whose host writes moves
        into shared memory: the audio callback posts each new one like
        :meth:`contact_move` (the host has checked them).
        """
        post = self._board.post_checked
        self._scheduler.intake = lambda: slots.drain(post)

    # -- monitoring -------------------------------------------------------------------

    def status(self) -> EngineStatus:
        """A snapshot of clock, voices, levels and counters."""
        with self._lock:
            self._reporter.drain()
            contacts = self._board.positions()
            running = self._running
        scheduler = self._scheduler
        mixer = scheduler.mixer
        load_p99, load_max = scheduler.render_load()
        return EngineStatus(
            backend=self._sink.backend,
            output_device=self._sink.output_device,
            sample_rate_hz=self.sample_rate_hz,
            block_frames=self.block_frames,
            channels=self.channels,
            now_frames=scheduler.frames,
            active_voices=scheduler.active_voices,
            active_contacts=contacts,
            levels=[float(level) for level in mixer.levels],
            peak=float(mixer.peak),
            underruns=int(self._sink.underruns),
            late_commands=scheduler.late_commands,
            muted_blocks=mixer.muted_blocks,
            limited_blocks=mixer.limited_blocks,
            output_latency_s=self._clock.output_latency_s,
            queue_depth=self._queue.depth,
            queue_capacity=self._queue.capacity,
            running=running,
            render_load_p99=load_p99,
            render_load_max=load_max,
        )
