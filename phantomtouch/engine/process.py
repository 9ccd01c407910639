"""The engine in a process of its own, for hosts whose other Python work holds the GIL.

The audio callback needs the interpreter lock for every block; in a process that also
serves web requests it waits for it. :class:`ProcessEngine` keeps the control side here
(:class:`~phantomtouch.engine.front.EngineFront`: the API, the job table, the contacts,
admission) and runs the audio side in a child process (``spawn``,
:mod:`phantomtouch.engine.child`), whose callback is the only thread there that does
Python work. Nothing here ever waits for the child:

- commands (a job's start with its plan, sent once per plan; releases; touchdowns) go
  through an :class:`~phantomtouch.engine.link.Outbox` whose thread writes them into a
  pipe; the callback reads them at the start of each block within a time budget;
- ``stop_all`` raises a sequence mark in shared memory that the callback reads first:
  every message sent before it is void, whatever the pipe holds;
- contact moves and the sample clock go through shared memory
  (:mod:`phantomtouch.engine.shared`), and so do the engine's figures and a heartbeat
  (:class:`~phantomtouch.engine.shared.StatusBlock`): ``status()`` reads them;
- a thread reads the child's reports (job starts and ends) into the job table.

A watchdog notices within ``STALL_S`` when the child dies or stops calling back
(killed, stopped, hung, its sound card gone): the engine's ``state`` says so, new work
is refused with DeviceError, every job and contact is dropped (``on_fault`` is told),
and a new child is started, again and again (``RETRY_MAX_S``) until its sound card
opens. When this process dies, the pipe closes and the child fades out and ends.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

from phantomtouch.engine.admission import RENDER_BUDGET
from phantomtouch.engine.checks import check_int
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.engine import RENDER_AHEAD_FRAMES
from phantomtouch.engine.front import (
    MAX_VOICES,
    ContactRecord,
    EngineFront,
    check_frame_number,
    check_server_time,
)
from phantomtouch.engine.jobs import Policy
from phantomtouch.engine.link import encode, read_frames
from phantomtouch.engine.prerender import PRERENDER_MAX_S, Prerendered
from phantomtouch.engine.scheduler import load_percentiles
from phantomtouch.engine.soundcard import SinkSpec
from phantomtouch.engine.spawn import CLOSE_TIMEOUT_S, START_TIMEOUT_S, EngineProcess, slim, spawn
from phantomtouch.errors import DeviceError, EngineBusyError
from phantomtouch.renderer.carriers import noise_key, noise_loop
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.clip import ClipCarrier
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import NoiseCarrier, PatternCarrier, SineCarrier

logger = logging.getLogger("phantomtouch.engine")

STALL_S = 0.5
"""A running engine process that has not called back for this long is stalled."""
WATCH_PERIOD_S = 0.1
RESTART_TIMEOUT_S = 10.0
"""Longest wait for a restarted engine process to open its sink (a sound card that
has just lost a client may hang a new one for a while): then it is tried again."""
RETRY_FIRST_S = 0.5
RETRY_MAX_S = 5.0
"""A restart that fails (the sound card is gone) is tried again after 0.5 s, then after
twice as long each time, at most every 5 s."""
PLAN_CACHE_BYTES = 32 << 20
"""Plans kept by the engine process, by their size on the wire."""
NOISE_LOOPS = 8
"""Noise loops the engine process keeps (as the renderer's cache does)."""
REALTIME_PRIORITY = 1
"""SCHED_FIFO priority of the engine process's threads (above every ordinary thread)."""


class ProcessEngine(EngineFront):
    """:class:`~phantomtouch.engine.Engine`'s API, with the audio side in a child process.

    Parameters
    ----------
    device : DeviceProfile
    sink : SinkSpec or None
        The sink the child opens; None: ``SinkSpec("default")``.
    queue_capacity, max_voices, contact, log_path, render_budget, voice_policy
        See :class:`~phantomtouch.engine.front.EngineFront` (the log is written here).
    render_ahead_frames : int, >= 0
    realtime_priority : int or None, 1 <= realtime_priority <= 99
        SCHED_FIFO priority of the child's threads; None, or no permission for it:
        ordinary scheduling.
    voice_cost, start_cost : float or None
        As for :class:`~phantomtouch.engine.Engine` (None: the child measures them).
    on_fault : callable or None
        Called as ``on_fault(state)`` (``"gone"`` or ``"stalled"``) from the watchdog
        thread once every job and contact was dropped, before the restart.

    Notes
    -----
    The child is started with ``spawn``: the host's main module must be importable
    without side effects (guarded by ``if __name__ == "__main__"``).

    Raises
    ------
    DeviceError
        The child could not open its sink (or did not answer within 60 s).
    ParameterError
        An argument is out of range.
    """

    def __init__(
        self,
        device: DeviceProfile,
        sink: SinkSpec | None = None,
        *,
        queue_capacity: int = 4096,
        max_voices: int = MAX_VOICES,
        contact: ContactSettings | None = None,
        log_path: str | Path | None = None,
        render_ahead_frames: int = RENDER_AHEAD_FRAMES,
        realtime_priority: int | None = REALTIME_PRIORITY,
        render_budget: float = RENDER_BUDGET,
        voice_policy: Policy = "steal-oldest",
        prerender_max_s: float = PRERENDER_MAX_S,
        voice_cost: float | None = None,
        start_cost: float | None = None,
        on_fault: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(
            device,
            queue_capacity=queue_capacity,
            max_voices=max_voices,
            contact=contact,
            log_path=log_path,
            render_budget=render_budget,
            voice_policy=voice_policy,
            prerender_max_s=prerender_max_s,
        )
        if realtime_priority is not None:
            check_int("realtime_priority", realtime_priority, 1, 99)
        check_int("render_ahead_frames", render_ahead_frames, 0, 1 << 20)
        self._spec = sink if sink is not None else SinkSpec()
        self._priority = realtime_priority
        self._options = {
            "queue_capacity": queue_capacity,
            "max_voices": max_voices,
            "contact": contact,
            "render_ahead_frames": render_ahead_frames,
            "costs": None if voice_cost is None else (voice_cost, start_cost or 0.0, voice_cost),
            "contact_slots": self._settings.max_contacts,
        }
        self.on_fault = on_fault
        self._state = "starting"
        self._started = False
        self._restarts = 0
        self._halt = threading.Event()
        self._child = self._start_child()
        self._admission.set_costs(self._child.costs)
        self._watchdog = threading.Thread(
            target=self._watch, name="phantomtouch-engine-watchdog", daemon=True
        )
        self._watchdog.start()

    # -- the child --------------------------------------------------------------------

    def _start_child(self, timeout_s: float = START_TIMEOUT_S) -> EngineProcess:
        child = spawn(
            self._device,
            self._spec,
            self._options,
            self._priority,
            self._settings.max_contacts,
            timeout_s=timeout_s,
        )
        child.reader = threading.Thread(
            target=self._read_reports, args=(child,), name="phantomtouch-reports", daemon=True
        )
        child.reader.start()
        return child

    def _read_reports(self, child: EngineProcess) -> None:
        for events in read_frames(child.reports_fd):
            self._apply_events(events)

    def _send(self, message: tuple[Any, ...]) -> None:
        """Queue a message for the child (the caller holds the lock; seq is message[1])."""
        if not self._child.outbox.put(encode(message)):
            raise EngineBusyError(
                "the engine process is not taking commands (its pipe is full); retry later"
            )

    def _next_seq(self) -> int:
        self._child.seq += 1
        return self._child.seq

    # -- faults -----------------------------------------------------------------------

    @property
    def state(self) -> str:
        """``starting``, ``running``, ``stalled``, ``gone``, ``restarting`` or ``closed``."""
        return self._state

    def _watch(self) -> None:
        while not self._halt.wait(WATCH_PERIOD_S):
            if self._state != "running":
                continue
            child = self._child
            if not child.process.is_alive():
                self._fault("gone")
            elif time.monotonic() - child.status.read()["beat_s"] > STALL_S:
                self._fault("stalled")

    def _fault(self, state: str) -> None:
        """Drop everything, tell ``on_fault``, replace the child."""
        logger.error("the engine process is %s; restarting it", state)
        with self._lock:
            if self._halt.is_set():
                return
            self._state = state
            self._jobs.forget_all(self.now_frames, fault=state)
            self._contacts.clear()
            self._admission.forget_starts()
        if self.on_fault is not None:
            try:
                self.on_fault(state)
            except Exception:
                logger.exception("on_fault failed")
        self._child.end(kill=True)
        admission = self._admission
        self._options["costs"] = (
            admission.voice_cost,
            admission.start_cost,
            admission.prerendered_cost,
        )
        delay_s = RETRY_FIRST_S
        while True:
            if not self._set_state("restarting"):
                return
            try:
                child = self._start_child(RESTART_TIMEOUT_S)
                child.outbox.put(encode(("start_sink", 0)))
            except Exception as exc:  # the sound card may be gone: try again, less often
                logger.error("the engine process could not be restarted: %s", exc)
                self._set_state("gone")
                self._halt.wait(delay_s)
                delay_s = min(RETRY_MAX_S, 2 * delay_s)
                continue
            with self._lock:
                closing = self._halt.is_set()
                if not closing:
                    self._child = child
                    self._restarts += 1
            if closing:  # closed while this one started
                child.end(kill=True)
                return
            self._wait_running(child, RESTART_TIMEOUT_S)
            if self._state == "running":
                return
            child.end(kill=True)
            self._halt.wait(delay_s)
            delay_s = min(RETRY_MAX_S, 2 * delay_s)

    def _wait_running(self, child: EngineProcess, timeout_s: float = START_TIMEOUT_S) -> None:
        deadline = time.monotonic() + timeout_s
        while not child.status.read()["running"]:
            if not child.process.is_alive() or time.monotonic() > deadline:
                self._set_state("gone")
                return
            time.sleep(0.01)
        self._set_state("running")

    def _set_state(self, state: str) -> bool:
        """Set the state unless the engine is closing; False when it is."""
        with self._lock:
            if self._halt.is_set():
                return False
            self._state = state
            return True

    # -- life cycle -------------------------------------------------------------------

    @property
    def pid(self) -> int | None:
        """Process id of the engine process."""
        return self._child.process.pid

    def start(self) -> None:
        """Start the child's sink and wait until it plays (no-op when running)."""
        with self._lock:
            if self._state == "closed":
                raise DeviceError("the engine is closed")
            if self._started:
                return
            self._started = True
            child = self._child
            self._send(("start_sink", 0))
        self._wait_running(child)
        if self._state != "running":
            raise DeviceError("the engine process did not start playing")

    def close(self) -> None:
        """Fade out, close the child's engine and sink, end the child. Idempotent."""
        with self._lock:
            if self._state == "closed":
                return
            self._state = "closed"
            self._halt.set()
            child = self._child
            child.outbox.put(encode(("close", 0)))
        child.outbox.close(CLOSE_TIMEOUT_S)
        self._watchdog.join()
        child.end(kill=False)
        self._ledger.close()

    # -- clock ------------------------------------------------------------------------

    @property
    def now_frames(self) -> int:
        return int(self._child.status.read()["now_frames"])

    def frames_at(self, server_time_s: float) -> int:
        return self._child.clock.frames_at(check_server_time(server_time_s))

    def time_at(self, frame: int) -> float:
        return self._child.clock.time_at(check_frame_number(frame))

    def _next_block_frame(self) -> int:
        return self.now_frames + self.block_frames

    def _check_ready(self) -> None:
        state = self._state
        if state in ("running", "starting"):
            return
        if state == "closed":
            raise DeviceError("the engine is closed")
        raise DeviceError(f"the engine process is {state}; it is being restarted, retry shortly")

    # -- the audio side, over the pipe ------------------------------------------------

    def _noise(self, carrier: PatternCarrier | None) -> None:
        """Send the noise loop a carrier needs, unless the child has it."""
        if carrier is None or isinstance(carrier, SineCarrier | ClipCarrier):
            return
        assert isinstance(carrier, NoiseCarrier) or hasattr(carrier, "low_hz")
        key = noise_key(carrier.low_hz, carrier.high_hz, carrier.seed, self.sample_rate_hz)
        sent = self._child.noise
        if key in sent:
            sent.move_to_end(key)
            return
        self._send(("noise", 0, key, noise_loop(*key)))
        sent[key] = None
        while len(sent) > NOISE_LOOPS:
            sent.popitem(last=False)

    def _send_start(
        self,
        job_id: str,
        plan: Plan,
        owner: str | None,
        frame: int | None,
        prerendered: Prerendered | None,
    ) -> None:
        child = self._child
        self._noise(plan.pattern.carrier)
        known = child.plans.pop(id(plan), None)
        if known is not None and known[1]() is plan:
            child.plans[id(plan)] = known  # the most recently used
            key, sent = known[0], None
            prerendered = None  # the engine process has it with the plan
        else:
            if known is not None:  # a plan gone since, whose id this one has
                child.forget.append(known[0])
                child.plan_bytes -= known[2]
            key, sent = self._next_seq(), slim(plan)
        forget, child.forget = child.forget, []
        message = ("start", self._next_seq(), job_id, key, sent, prerendered, forget, owner, frame)
        frame_bytes = encode(message)
        if not child.outbox.put(frame_bytes):
            child.forget = forget + child.forget
            raise EngineBusyError(
                "the engine process is not taking commands (its pipe is full); retry later"
            )
        if sent is not None:
            size = len(frame_bytes)
            child.plans[id(plan)] = (key, weakref.ref(plan), size)
            child.plan_bytes += size
            while child.plan_bytes > PLAN_CACHE_BYTES and len(child.plans) > 1:
                old_key, _, old_size = child.plans.popitem(last=False)[1]
                child.forget.append(old_key)
                child.plan_bytes -= old_size

    def _send_release(self, job_id: str, frame: int | None, fade_frames: int | None) -> None:
        with contextlib.suppress(EngineBusyError):  # a full pipe: the job ends on its own
            self._send(("release", self._next_seq(), job_id, frame, fade_frames))

    def _send_down(self, owner: str, contact: str, record: ContactRecord, **kw: Any) -> None:
        slots = self._child.slots
        if record.slot is None:
            fresh = slots.allocate()
            if fresh is None:
                raise EngineBusyError(f"all {slots.capacity} contact slots are taken")
        else:
            fresh = (record.slot[0], slots.renew())
        try:
            self._noise(kw["carrier"])
            self._send(("down", self._next_seq(), owner, contact, fresh, kw))
        except BaseException:
            if record.slot is None:
                slots.release(fresh[0])
            raise
        record.slot = fresh

    def _send_move(
        self,
        owner: str,
        contact: str,
        record: ContactRecord,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        if record.slot is not None:
            slot, generation = record.slot
            self._child.slots.write(slot, generation, record.x_cm, record.y_cm, intensity, frame)

    def _send_up(self, owner: str, contact: str, record: ContactRecord | None, **kw: Any) -> None:
        if record is not None and record.slot is not None:
            self._child.slots.release(record.slot[0])
        with contextlib.suppress(EngineBusyError):
            self._send(("up", self._next_seq(), owner, contact, kw))

    def _send_release_owner(self, owner: str, records: list[ContactRecord]) -> None:
        for record in records:
            if record.slot is not None:
                self._child.slots.release(record.slot[0])
        with contextlib.suppress(EngineBusyError):
            self._send(("release_owner", self._next_seq(), owner))

    def _send_stop_all(self, records: list[ContactRecord]) -> None:
        child = self._child
        for record in records:
            if record.slot is not None:
                child.slots.release(record.slot[0])
        child.mark.value = self._next_seq()

    def _figures(self) -> dict[str, Any]:
        figures = self._child.status.read()
        load_p99, load_max = load_percentiles(self._child.loads)
        figures.update(
            render_load_p99=load_p99,
            render_load_max=load_max,
            backend=self._child.backend,
            output_device=self._child.output_device,
            state=self._state,
            restarts=self._restarts,
            running=figures["running"] and self._state == "running",
        )
        return figures
