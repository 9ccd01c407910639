"""The engine process: one audio callback that does all of its Python work.

:func:`serve` runs in the engine process of a
:class:`~phantomtouch.engine.process.ChildAudio`. It opens the sink a
:class:`~phantomtouch.engine.soundcard.SinkSpec` names, builds a
:class:`~phantomtouch.engine.core.Core`, measures what a voice costs and reports ready
(non real time); from then on it refuses to build a noise loop it was not handed
(:func:`~phantomtouch.renderer.carriers.refuse_building`). Once told to start, it starts
the sink, and its main thread only waits (in a call that holds no interpreter lock) for
the host to leave. Everything else happens in the audio callback, in real time, at the
start of each block (:meth:`Intake.run`):

1. report what the last block did (events to the host, figures and a heartbeat into
   shared memory), and unmap the noise loops no voice reads any more;
2. apply a ``stop_all`` the host raised in shared memory: every message sent before it
   is void;
3. read the host's messages (``(seq, message)``) from a non-blocking pipe and perform
   them (:func:`~phantomtouch.engine.messages.perform`), while the time spent stays
   within ``INTAKE_SHARE`` of the block's playing time (at least one message a block;
   the rest wait for the next block);
4. take the newest contact positions from shared memory.

So the callback never waits for the interpreter lock: no other thread of this process
runs Python code while audio plays. When the host's pipe closes (the host is gone), the
engine fades out and the process ends.
"""

from __future__ import annotations

import gc
import logging
import os
import signal
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.core import Core, measure_costs
from phantomtouch.engine.engine import RENDER_AHEAD_RINGS, cost_plan
from phantomtouch.engine.link import FrameReader, NonBlockingWriter, encode, widen
from phantomtouch.engine.messages import AudioState, Close, PlanReleased, StartSink, perform
from phantomtouch.engine.noise import HeldLoops
from phantomtouch.engine.plan_memory import HeldArrays
from phantomtouch.engine.shared import MoveSlots, SharedClock, StatusBlock
from phantomtouch.engine.soundcard import SinkSpec
from phantomtouch.renderer.carriers import refuse_building
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger(__name__)

INTAKE_SHARE = 0.15
"""Share of a block's playing time the callback spends on the host's messages."""
READ_BYTES = 1 << 18
"""Most bytes read from the host's pipe per block."""


class Intake:
    """The engine process's state, used by its audio callback at each block's start."""

    def __init__(
        self,
        core: Core,
        reader: FrameReader,
        writer: NonBlockingWriter,
        mark: Any,
        slots: MoveSlots,
        status: StatusBlock,
    ) -> None:
        self.core = core
        self.reader = reader
        self.writer = writer
        self.mark = mark
        self.slots = slots
        self.status = status
        self.state = AudioState(core, slots=slots)
        self.state.loops = HeldLoops(self.state.reports)
        self.state.arrays = HeldArrays()
        self.handled_mark = 0
        self.leave = threading.Event()
        period_s = core.device.block_frames / core.device.sample_rate_hz
        self.budget_s = INTAKE_SHARE * period_s
        self.figures: dict[str, Any] = core.figures()

    def run(self) -> None:
        """At the start of each block (real time; see the module docstring)."""
        began = time.perf_counter()
        self.report()
        self.check_mark()
        reader = self.reader
        reader.fill(READ_BYTES)
        while (framed := reader.next()) is not None:
            self.check_mark()
            self.apply(framed)
            if time.perf_counter() - began > self.budget_s:
                break
        if reader.closed and reader.pending_bytes == 0:
            self.leave.set()  # the host is gone
        self.slots.drain(self.core.board.post_checked)

    def report(self) -> None:
        """Send the last block's events, write figures and a heartbeat (real time)."""
        core = self.core
        scheduler = core.scheduler
        state = self.state
        self.status.beat(time.monotonic(), scheduler.frames)
        assert state.loops is not None and state.arrays is not None
        state.loops.collect()
        events = core.events()
        events.extend(PlanReleased(handle) for handle in state.arrays.collect())
        if state.reports:
            events.extend(state.reports)
            state.reports.clear()
        if events:
            self.writer.send(events)
        else:
            self.writer.flush()
        figures = self.figures  # the render loads are in shared memory: the host's to sum up
        mixer = scheduler.mixer
        figures.update(
            now_frames=scheduler.frames,
            active_voices=scheduler.active_voices,
            underruns=core.sink.underruns,
            late_commands=scheduler.late_commands,
            muted_blocks=mixer.muted_blocks,
            limited_blocks=mixer.limited_blocks,
            peak=mixer.peak,
            queue_depth=core.queue.depth,
            levels=mixer.levels,
            callback_errors=scheduler.callback_errors,
            output_latency_s=core.clock.output_latency_s,
            dropped_reports=self.writer.dropped,
            refused_commands=state.refused,
            running=core.running,
        )
        self.status.write(figures)

    def check_mark(self) -> None:
        """Apply a ``stop_all`` the host raised (real time)."""
        mark = int(self.mark.value)
        if mark > self.handled_mark:
            self.handled_mark = mark
            self.core.stop_all()
            self.slots.unbind_all()

    def apply(self, framed: tuple[int, Any]) -> None:
        """Perform one ``(seq, message)`` of the host (real time); one sent before the
        last ``stop_all`` is void. Checked by the host: a failure here is a bug, counted
        as a callback error, never a stop."""
        seq, message = framed
        try:
            perform(self.state, message, void=seq < self.handled_mark)
        except Exception as exc:
            scheduler = self.core.scheduler
            scheduler.callback_errors += 1
            scheduler.last_error = exc
        if self.state.leave:
            self.leave.set()

    def close(self) -> None:
        """Non real time: fade out and close (a capture sink writes its WAV as it closes)."""
        self.core.close(fade=True)


def raise_priority(priority: int | None) -> None:
    """Run this thread, and the threads it starts, with SCHED_FIFO ``priority``.

    Linux only: elsewhere the sound card's callback thread already runs at real-time
    priority (PortAudio's WASAPI, ASIO and CoreAudio host APIs), and this does nothing.
    """
    if priority is None or sys.platform != "linux" or not hasattr(os, "sched_setscheduler"):
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        logger.info("engine process keeps normal priority: %s", exc)


def _wait_for_start(intake: Intake) -> bool:
    """Perform the host's messages until it says ``StartSink`` (True) or ``Close``
    (non real time, before the sink starts)."""
    reader = intake.reader
    os.set_blocking(reader.fd, True)
    try:
        while not reader.closed:
            reader.fill(READ_BYTES)
            while (framed := reader.next()) is not None:
                if isinstance(framed[1], StartSink):
                    return True
                if isinstance(framed[1], Close):
                    return False
                intake.apply(framed)
        return False
    finally:
        os.set_blocking(reader.fd, False)


def serve(
    commands: Connection,
    reports: Connection,
    device_json: str,
    spec: SinkSpec,
    options: dict[str, Any],
    mark: Any,
    priority: int | None,
    shared: dict[str, Any],
) -> None:
    """The engine process's main function (the target of the child process; non real
    time until the sink starts).

    Parameters
    ----------
    commands : Connection
        The host's ``(seq, message)`` pairs (read end; framed by
        :mod:`phantomtouch.engine.link`).
    reports : Connection
        Where the engine reports (write end): first ``("ready", (voice_cost,
        start_cost, prerendered_cost), backend, output_device)`` or ``("failed",
        exception)``, then lists of events (:mod:`phantomtouch.engine.messages`).
    device_json : str
        The device profile as JSON.
    spec : SinkSpec
    options : dict
        ``queue_capacity``, ``max_voices``, ``contact``, ``render_ahead_frames``,
        ``costs`` (``(voice_cost, start_cost, prerendered_cost)``; None: measure them),
        ``contact_slots``.
    mark : multiprocessing.Value
        Sequence number of the host's last ``stop_all``.
    priority : int or None
        SCHED_FIFO priority for this process's threads.
    shared : dict
        The shared memory: ``clock``, ``slots`` and ``slot_count``, ``status``, ``loads``
        (the scheduler's render loads).
    """
    # Ctrl+C and a SIGTERM to the group (`timeout`, a service manager) reach this process
    # too: the host closes the engine (with its fade-out); without a host, the closed pipe
    # ends this process
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise_priority(priority)
    report_fd = reports.fileno()
    try:
        device = DeviceProfile.model_validate_json(device_json)
        clock = SampleClock(
            device.sample_rate_hz,
            publish=SharedClock(device.sample_rate_hz, shared["clock"]).publish,
        )
        slots = MoveSlots(shared["slot_count"], shared["slots"])
        status = StatusBlock(device.channels, shared["status"])
        sink = spec.open(device)
        core = Core(
            device,
            sink,
            settings=options["contact"] or ContactSettings(),
            # admission is the host's: the queue only bounds what it let through
            queue_capacity=options["queue_capacity"] + 2 * options["contact_slots"] + 1,
            rings=min(options["max_voices"], RENDER_AHEAD_RINGS),
            chunk_frames=options["render_ahead_frames"],
            clock=clock,
            render_loads=np.frombuffer(shared["loads"], dtype=np.float64),
        )
        costs = options["costs"]
        if costs is None:
            chunk = options["render_ahead_frames"]
            costs = (
                measure_costs(device, cost_plan(device), chunk_frames=chunk)
                if sink.realtime
                else (0.0, 0.0, 0.0)
            )
    except Exception as exc:
        os.write(report_fd, encode(("failed", exc)))
        return
    widen(commands.fileno())
    intake = Intake(
        core, FrameReader(commands.fileno()), NonBlockingWriter(report_fd), mark, slots, status
    )
    core.scheduler.intake = intake.run
    refuse_building()  # from now on a noise loop is only what the host hands over
    os.set_blocking(report_fd, True)
    os.write(report_fd, encode(("ready", costs, sink.backend, sink.output_device)))
    os.set_blocking(report_fd, False)
    gc.freeze()  # what start-up made is never scanned again: collections stay short
    if not _wait_for_start(intake):
        core.close(fade=False)
        return
    sys.setswitchinterval(0.001)
    core.start()
    intake.leave.wait()
    intake.close()
