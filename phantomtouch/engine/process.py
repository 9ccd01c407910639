"""The audio side in an engine process of its own (:class:`ChildAudio`, host only) and
:class:`ProcessEngine`, the front over it: for hosts whose other Python work holds the
interpreter lock the audio callback needs. Nothing here waits for the engine process;
``docs/engine.md`` (Transports, Faults) says what crosses how, and what the watchdog does.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from phantomtouch.engine.checks import check_int
from phantomtouch.engine.front import EngineFront, Links
from phantomtouch.engine.messages import (
    RELEASES,
    Close,
    Command,
    ContactMove,
    HoldPlan,
    NoiseReleased,
    PlanReleased,
    SetWearerGains,
    StartSink,
)
from phantomtouch.engine.noise import SharedLoops, loop_key
from phantomtouch.engine.plan_memory import SharedPlans
from phantomtouch.engine.scheduler import load_percentiles, ring_percentiles
from phantomtouch.engine.spawn import CLOSE_TIMEOUT_S, START_TIMEOUT_S, ChildProcess
from phantomtouch.errors import DeviceError, EngineBusyError
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.renderer.carriers import noise_loop
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger("phantomtouch.engine")

STALL_S = 0.5
"""A running engine process that has not called back for this long is stalled."""
WATCH_PERIOD_S = 0.1
RESTART_TIMEOUT_S = 10.0
"""Longest wait for a restarted engine process to open its sink (a sound card that
has just lost a client may hang a new one for a while): then it is tried again."""
RETRY_FIRST_S = 0.5
RETRY_MAX_S = 5.0
"""Waits before a failed restart is tried again, s: doubled each time (docs/engine.md)."""
REALTIME_PRIORITY = 1
"""SCHED_FIFO priority of the engine process's threads (above every ordinary thread)."""


class ChildAudio:
    """The audio side in an engine process (module docstring); arguments as for
    :class:`ProcessEngine`. Host only."""

    def __init__(
        self,
        device: DeviceProfile,
        spec: SinkSpec,
        links: Links,
        priority: int | None,
        on_fault: Callable[[str], None] | None,
    ) -> None:
        self._device = device
        self._links = links
        self._options = {
            "queue_capacity": links.queue_capacity,
            "max_voices": links.max_voices,
            "contact": links.settings,
            "costs": links.costs,
        }
        self._spawn = functools.partial(
            ChildProcess, device, spec, self._options, priority, self._read_reports
        )
        self.on_fault = on_fault
        self.state = "starting"
        self._started = False
        self.restarts = 0
        self._wearer: SetWearerGains | None = None
        self._lock = threading.RLock()
        self._halt = threading.Event()
        self._loops = SharedLoops()
        self._shared_plans = SharedPlans()
        self._seq = 0
        self._child = self._spawn(START_TIMEOUT_S)
        self.costs = self._options["costs"] = self._child.costs  # a restart measures nothing
        self.backend = self._child.backend
        self.output_device = self._child.output_device
        self.device = self._device = device.at_block(self._child.block_frames)
        """The device at the block the engine process's sink found (its period)."""
        self.period_frames = self._child.period_frames
        self.period_source = self._child.period_source
        # a restarted engine process keeps this block (or fails to start, and is retried)
        self._spawn = functools.partial(
            ChildProcess,
            self.device,
            dataclasses.replace(spec, period_frames=self.device.block_frames),
            self._options,
            priority,
            self._read_reports,
        )
        self._watchdog = threading.Thread(
            target=self._watch, name="phantomtouch-engine-watchdog", daemon=True
        )
        self._watchdog.start()

    def _reset_records(self) -> None:
        """Forget what an engine process held (none is running, or a new one starts)."""
        self._seq = 0
        self._loops.clear()
        self._shared_plans.clear()

    # -- the engine process ---------------------------------------------------------------

    def _read_reports(self, child: ChildProcess) -> None:
        """Host, the reports thread: free what was released, hand every event to the front."""
        while True:
            try:
                events = child.reports.recv()
            except (EOFError, OSError):
                return
            if child is getattr(self, "_child", None):  # not a process replaced since
                for event in events:
                    if isinstance(event, NoiseReleased):
                        self._loops.released(event.key)
                    elif isinstance(event, PlanReleased):
                        self._shared_plans.released(event.handle)
            self._links.deliver(events)

    def _write(self, child: ChildProcess, message: Command) -> bool:
        self._seq += 1
        return child.outbox.put((self._seq, message), release=isinstance(message, RELEASES))

    def post(self, message: Command) -> None:
        """Queue a message for the engine process (host, under the front's lock); a
        plan handed over crosses as :meth:`SharedPlans.share` makes it.

        Raises
        ------
        EngineBusyError
            The pipe is full (the engine process does not read); never for a release
            (``RELEASES``), which only a closed or broken pipe refuses.
        """
        if isinstance(message, HoldPlan):
            shared = self._shared_plans.share(message.handle, message.plan, message.prerendered)
            message = HoldPlan(message.handle, *shared)
        if isinstance(message, SetWearerGains):
            self._wearer = message  # a restarted engine process gets it again
        if not self._write(self._child, message):
            raise EngineBusyError(
                "the engine process is not taking commands (its pipe is full); retry later"
            )

    def prepare(self, carrier: object) -> None:
        """Compute a carrier's noise loop ahead, cached by the renderer (host, outside the
        front's lock)."""
        key = loop_key(carrier, self._device.sample_rate_hz)
        if key is not None:
            noise_loop(*key)

    def provide(self, carrier: object) -> None:
        """Hand the engine process the carrier's noise loop unless it holds it (host,
        under the front's lock, before the message that needs it)."""
        self._loops.provide(loop_key(carrier, self._device.sample_rate_hz), self.post)

    def claim_slot(self, held: tuple[int, int] | None) -> tuple[int, int] | None:
        """A move slot for a touchdown: a fresh one, or ``held`` renewed (host, under the
        front's lock).

        Raises
        ------
        EngineBusyError
            Every slot is taken.
        """
        slots = self._child.slots
        if held is not None:
            return (held[0], slots.renew())
        fresh = slots.allocate()
        if fresh is None:
            raise EngineBusyError(f"all {slots.capacity} contact slots are taken")
        return fresh

    def free_slot(self, slot: tuple[int, int] | None) -> None:
        """Give a contact's slot back (host, under the front's lock)."""
        if slot is not None:
            self._child.slots.release(slot[0])

    def move(self, slot: tuple[int, int] | None, message: ContactMove) -> None:
        """Write a checked move into the contact's slot (host, under the front's lock)."""
        if slot is not None:
            self._child.slots.write(*slot, message.unit_gains, message.intensity, message.frame)

    def stop_all(self) -> None:
        """Raise the stop mark: everything posted so far is void (host)."""
        self._seq += 1
        self._child.mark.value = self._seq

    def sync(self) -> None:
        """Nothing to collect: a host thread reads the reports as they come."""

    # -- faults ---------------------------------------------------------------------------

    def _watch(self) -> None:
        while not self._halt.wait(WATCH_PERIOD_S):
            if self.state != "running":
                continue
            child = self._child
            if not child.process.is_alive():
                self._fault("gone")
            elif time.monotonic() - child.status.read()["beat_s"] > STALL_S:
                self._fault("stalled")

    def _fault(self, state: str) -> None:
        """Drop everything, tell the front and ``on_fault``, replace the engine process
        (a process that ends while the engine closes is no fault)."""
        if not self._set_state(state):
            return
        logger.error("the engine process is %s; restarting it", state)
        self._links.lost(state)
        if self.on_fault is not None:
            try:
                self.on_fault(state)
            except Exception:
                logger.exception("on_fault failed")
        self._child.end(kill=True)
        delay_s = RETRY_FIRST_S
        while self._set_state("restarting"):
            try:
                child = self._spawn(RESTART_TIMEOUT_S)
            except Exception as exc:  # the sound card may be gone: try again, less often
                logger.error("the engine process could not be restarted: %s", exc)
                self._set_state("gone")
            else:
                child.outbox.put((0, StartSink()))
                if self._wearer is not None:
                    child.outbox.put((0, self._wearer))
                with self._lock:
                    adopted = not self._halt.is_set()  # not closed while this one started
                    if adopted:
                        self._reset_records()
                        self._child = child
                        self.restarts += 1
                if adopted and self._wait_running(child, RESTART_TIMEOUT_S):
                    return
                child.end(kill=True)
            self._halt.wait(delay_s)
            delay_s = min(RETRY_MAX_S, 2 * delay_s)

    def _wait_running(self, child: ChildProcess, timeout_s: float) -> bool:
        """Wait until ``child`` plays: True, the state is ``running``; else ``gone``."""
        deadline = time.monotonic() + timeout_s
        while not child.status.read()["running"]:
            if not child.process.is_alive() or time.monotonic() > deadline:
                self._set_state("gone")
                return False
            time.sleep(0.01)
        return self._set_state("running")

    def _set_state(self, state: str) -> bool:
        """Set the state unless the engine is closing; False when it is."""
        with self._lock:
            if self._halt.is_set():
                return False
            self.state = state
            return True

    # -- life cycle -----------------------------------------------------------------------

    @property
    def pid(self) -> int | None:
        return self._child.process.pid

    def start(self) -> None:
        """Start the engine process's sink and wait until it plays (no-op when running)."""
        with self._lock:
            if self.state == "closed":
                raise DeviceError("the engine is closed")
            if self._started:
                return
            self._started = True
            child = self._child
            self._write(child, StartSink())
        if not self._wait_running(child, START_TIMEOUT_S):
            raise DeviceError("the engine process did not start playing")

    def close(self) -> None:
        """Fade out, close the engine process's sink, end it, free the shared loops.
        Idempotent."""
        with self._lock:
            if self.state == "closed":
                return
            self.state = "closed"
            self._halt.set()
            child = self._child
            self._write(child, Close())
        child.outbox.close(CLOSE_TIMEOUT_S)
        self._watchdog.join()
        child.end(kill=False)
        self._reset_records()

    # -- clock and figures ----------------------------------------------------------------

    @property
    def now_frames(self) -> int:
        return int(self._child.status.read()["now_frames"])

    def frames_at(self, server_time_s: float) -> int:
        return self._child.clock.frames_at(server_time_s)

    def time_at(self, frame: int) -> float:
        return self._child.clock.time_at(frame)

    def next_block_frame(self) -> int:
        return self.now_frames + self._device.block_frames

    def check_ready(self) -> None:
        """Raise DeviceError unless the engine process takes commands."""
        state = self.state
        if state == "closed":
            raise DeviceError("the engine is closed")
        if state not in ("running", "starting"):
            raise DeviceError(
                f"the engine process is {state}; it is being restarted, retry shortly"
            )

    def figures(self) -> dict[str, Any]:
        figures = self._child.status.read()
        load_p99, load_max = load_percentiles(self._child.loads)
        times = ring_percentiles(self._child.seconds)
        figures.update(
            render_load_p99=load_p99,
            render_load_max=load_max,
            callback_p50_s=times[0],
            callback_p99_s=times[1],
            callback_max_s=times[2],
            period_frames=self.period_frames,
            period_source=self.period_source,
            backend=self.backend,
            output_device=self.output_device,
            state=self.state,
            restarts=self.restarts,
            running=figures["running"] and self.state == "running",
        )
        return figures


class ProcessEngine(EngineFront):
    """An :class:`~phantomtouch.engine.front.EngineFront` over a :class:`ChildAudio`: the
    engine's API in this process, its audio side in an engine process.

    Parameters
    ----------
    device : DeviceProfile
    sink : SinkSpec or None
        The sink the engine process opens; None: ``SinkSpec("default")``.
    realtime_priority : int or None, 1 <= realtime_priority <= 99
        SCHED_FIFO priority of the engine process's threads; None, or no permission for
        it: ordinary scheduling.
    on_fault : callable or None
        Called as ``on_fault(state)`` (``"gone"`` or ``"stalled"``) from the watchdog
        thread once every job and contact was dropped, before the restart.
    **options
        The keywords of :class:`~phantomtouch.engine.front.EngineFront` (the log is
        written in this process).

    Notes
    -----
    The engine process is started with ``spawn``: the host's main module must be
    importable without side effects (guarded by ``if __name__ == "__main__"``).

    Raises
    ------
    DeviceError
        The engine process could not open its sink (or did not answer within 60 s).
    ParameterError
        An argument is out of range.
    """

    def __init__(
        self,
        device: DeviceProfile,
        sink: SinkSpec | None = None,
        *,
        realtime_priority: int | None = REALTIME_PRIORITY,
        on_fault: Callable[[str], None] | None = None,
        **options: Any,
    ) -> None:
        if realtime_priority is not None:
            check_int("realtime_priority", realtime_priority, 1, 99)
        super().__init__(
            device,
            lambda links: ChildAudio(
                device, sink if sink is not None else SinkSpec(), links, realtime_priority, on_fault
            ),
            **options,
        )

    _audio: ChildAudio

    @property
    def state(self) -> str:
        """``starting``, ``running``, ``stalled``, ``gone``, ``restarting`` or ``closed``
        (host, any thread)."""
        return self._audio.state

    @property
    def pid(self) -> int | None:
        """Process id of the engine process (host, any thread)."""
        return self._audio.pid
