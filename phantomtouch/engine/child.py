"""The engine process (:func:`serve`): its audio callback does its Python work at each
block's start (:meth:`Intake.run`; ``docs/engine.md``, Threads)."""

from __future__ import annotations

import dataclasses
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
from phantomtouch.engine.core import Core
from phantomtouch.engine.link import Inbox, ReportBox
from phantomtouch.engine.local_audio import RENDER_AHEAD_FRAMES, RENDER_AHEAD_RINGS, voice_costs
from phantomtouch.engine.messages import AudioState, Close, Event, PlanReleased, StartSink, perform
from phantomtouch.engine.messages import prepare as prepare_message
from phantomtouch.engine.noise import HeldLoops
from phantomtouch.engine.plan_memory import HeldArrays
from phantomtouch.engine.shared import MoveSlots, SharedClock, StatusBlock
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.renderer.carriers import refuse_building
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger(__name__)

INTAKE_SHARE = 0.15
"""Share of a block's playing time the callback spends on the host's messages."""
MESSAGES_PER_BLOCK = 256
"""Most of the host's messages the callback performs per block."""
REPORT_EVERY_S = 0.01
"""How often the callback hands its events to the report box (waking its thread once the
block is rendered), unmaps what no voice reads, and writes its figures into the status
block, s (rounded to whole blocks); the heartbeat is written every block."""


@dataclasses.dataclass
class Intake:
    """The engine process's state, used by its audio callback at each block's start."""

    core: Core
    inbox: Inbox
    report_box: ReportBox
    mark: Any
    """Sequence number of the host's last ``stop_all`` (shared memory)."""
    slots: MoveSlots
    status: StatusBlock

    def __post_init__(self) -> None:
        self.state = AudioState(self.core, slots=self.slots)
        self.loops = self.state.loops = HeldLoops(self.state.reports)
        self.arrays = self.state.arrays = HeldArrays()
        self.handled_mark = 0
        self.leave = threading.Event()
        device = self.core.device
        self.budget_s = INTAKE_SHARE * (device.block_frames / device.sample_rate_hz)
        self.report_every = max(
            1, round(REPORT_EVERY_S * device.sample_rate_hz / device.block_frames)
        )
        self._blocks = 0
        self._reported = False
        self.report_box.chores = self.chores

    def run(self) -> None:
        """At the start of each block (real time): the host's messages come from the
        inbox's FIFO, without a system call or an unpickling."""
        began = time.perf_counter()
        self.report()
        self.check_mark()
        inbox = self.inbox
        messages = inbox.messages
        for _ in range(MESSAGES_PER_BLOCK):
            if not messages:
                break
            self.check_mark()
            self.apply(messages.popleft())
            if time.perf_counter() - began > self.budget_s:
                break
        if inbox.drained:
            self.leave.set()  # the host is gone
        self.slots.drain(self.core.board.post_checked)

    def report(self) -> None:
        """Write a heartbeat, and every ``report_every`` blocks queue the events since for
        the report box, whose thread :meth:`finished` wakes once the block is rendered
        (real time)."""
        core = self.core
        self.status.beat(time.monotonic(), core.scheduler.frames)
        self._blocks += 1
        if self._blocks % self.report_every:
            return
        self._reported = True
        state = self.state
        events = core.events()
        if taken := len(state.reports):  # other threads append too: take what is there
            events.extend(state.reports[:taken])
            del state.reports[:taken]
        if events:
            self.report_box.put(events)

    def finished(self) -> None:
        """At the end of the callback (real time): when one of its blocks reported, wake
        the report box's thread, so that no thread wakes to take the interpreter's lock
        while a block renders, and one is woken at most every ``report_every`` blocks."""
        if self._reported:
            self._reported = False
            self.report_box.wake()

    def chores(self) -> list[Event]:
        """What the callback leaves to the report box's thread, which does it each time a
        block reported (non real time; :attr:`ReportBox.chores
        <phantomtouch.engine.link.ReportBox.chores>`): unmap what no voice reads any more
        (a system call, and for a block still read a raised ``BufferError``) and write
        the figures (a few dozen reads of the engine's counters). The noise loops freed
        are reported with the callback's next events; the plans' blocks freed, returned."""
        self.loops.collect()
        released: list[Event] = [PlanReleased(handle) for handle in self.arrays.collect()]
        figures = self.core.figures(loads=False)  # the render loads: the host's to sum up
        figures.update(dropped_reports=self.report_box.dropped, refused_commands=self.state.refused)
        self.status.write(figures)
        return released

    def check_mark(self) -> None:
        """Apply a ``stop_all`` the host raised (real time)."""
        mark = int(self.mark.value)
        if mark > self.handled_mark:
            self.handled_mark = mark
            self.core.stop_all()
            self.slots.unbind_all()

    def prepare(self, framed: tuple[int, Any]) -> tuple[int, Any] | None:
        """Prepare one ``(seq, message)`` of the host (non real time: the inbox thread;
        :func:`~phantomtouch.engine.messages.prepare`); None: nothing left to perform."""
        try:
            staged = prepare_message(self.state, framed[1])
        except Exception as exc:  # a bug, counted as in `apply`
            self.core.scheduler.callback_errors += 1
            self.core.scheduler.last_error = exc
            return None
        return None if staged is None else (framed[0], staged)

    def apply(self, framed: tuple[int, Any]) -> None:
        """Perform one ``(seq, message)`` of the host (real time); one sent before the
        last ``stop_all`` is void. Checked by the host: a failure here is a bug, counted
        as a callback error, never a stop."""
        seq, message = framed
        try:
            perform(self.state, message, void=seq < self.handled_mark)
        except Exception as exc:
            self.core.scheduler.callback_errors += 1
            self.core.scheduler.last_error = exc
        if self.state.leave:
            self.leave.set()


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
    """Receive and perform the host's messages until it says ``StartSink`` (True) or
    ``Close`` (non real time, the main thread, before the sink and the inbox start)."""
    while True:
        try:
            framed = intake.inbox.connection.recv()
        except (EOFError, OSError):
            return False
        if isinstance(framed[1], (StartSink, Close)):
            return isinstance(framed[1], StartSink)
        intake.apply(framed)


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
        The host's ``(seq, message)`` pairs (read end; received by the main thread
        until the sink starts, then by the inbox's thread).
    reports : Connection
        Where the engine reports (write end): first ``("ready", (voice_cost,
        start_cost, prerendered_cost), backend, output_device, (block_frames,
        period_frames, period_source))`` or ``("failed", exception)``, then lists of
        events (:mod:`phantomtouch.engine.messages`), sent by the report box's thread.
    device_json : str
        The device profile as JSON; the engine plays it at the block its sink found
        (the sound card's period, :class:`~phantomtouch.output.sinks.Sink`).
    spec : SinkSpec
    options : dict
        ``queue_capacity``, ``max_voices``, ``contact`` (one move slot per
        ``contact.max_contacts``) and ``costs`` (``(voice_cost, start_cost,
        prerendered_cost)``; None: measure them).
    mark : multiprocessing.Value
        Sequence number of the host's last ``stop_all``.
    priority : int or None
        SCHED_FIFO priority for this process's threads.
    shared : dict
        The shared memory: ``clock``, ``slots``, ``status``, ``loads`` and
        ``seconds`` (the scheduler's render loads and callback times).
    """
    # Ctrl+C and a SIGTERM to the group (`timeout`, a service manager) reach this process
    # too: the host closes the engine (with its fade-out); without a host, the closed pipe
    # ends this process
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        device = DeviceProfile.model_validate_json(device_json)
        clock = SampleClock(
            device.sample_rate_hz,
            publish=SharedClock(device.sample_rate_hz, shared["clock"]).publish,
        )
        slots = MoveSlots(options["contact"].max_contacts, device.channels, shared["slots"])
        status = StatusBlock(device.channels, shared["status"])
        sink = spec.open(device)  # first: the sound card's period is the engine's block
        device = device.at_block(sink.block_frames)
        core = Core(
            device,
            sink,
            settings=options["contact"],
            # admission is the host's: the queue only bounds what it let through
            queue_capacity=options["queue_capacity"] + 2 * slots.capacity + 1,
            rings=min(options["max_voices"], RENDER_AHEAD_RINGS),
            chunk_frames=RENDER_AHEAD_FRAMES,
            clock=clock,
            render_loads=np.frombuffer(shared["loads"], dtype=np.float64),
            render_seconds=np.frombuffer(shared["seconds"], dtype=np.float64),
        )
        costs = options["costs"]
        if costs is None:
            costs = voice_costs(core) if sink.realtime else (0.0, 0.0, 0.0)
    except Exception as exc:
        reports.send(("failed", exc))
        return
    refuse_building()  # from now on a noise loop is only what the host hands over
    period = (sink.block_frames, sink.period_frames, sink.period_source)
    reports.send(("ready", costs, sink.backend, sink.output_device, period))
    # Real time from here on, for this thread and those it starts (the report box's, the
    # inbox's, the render-ahead and the sink's threads): not the start-up above, whose
    # second of CPU (the compiled loops loaded, the voices' costs measured) would hold
    # off every other engine at that priority on the machine (docs/engine.md)
    raise_priority(priority)
    intake = Intake(
        core,
        Inbox(commands, poll_s=device.block_frames / device.sample_rate_hz),
        ReportBox(reports),
        mark,
        slots,
        status,
    )
    core.scheduler.intake = intake.run
    core.scheduler.finished = intake.finished
    gc.freeze()  # what start-up made is never scanned again: collections stay short
    if not _wait_for_start(intake):
        core.close(fade=False)
        return
    sys.setswitchinterval(0.001)
    intake.inbox.start(intake.prepare)
    core.start()
    intake.leave.wait()
    core.close(fade=True)  # a capture sink writes its WAV as it closes
