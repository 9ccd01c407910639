"""The engine in a process of its own, for hosts whose other Python work holds the GIL.

The audio callback needs the interpreter lock for every block. In a process that also
serves web requests, a thread busy with Python work (JSON, pydantic) holds the lock for
a switch interval (5 ms) at a time, longer than a 2.67 ms block of 128 frames:
``benchmarks/bench_engine.py`` measures the underruns that follow, and how they vanish
when the engine runs in a process of its own. :class:`ProcessEngine` is that remedy
with the :class:`~phantomtouch.engine.Engine` API: a child process (``spawn``) owns the
sink and a real ``Engine``; this process keeps a thin proxy.

- Calls that answer (``schedule``, ``contact_down``, ``stop``, ``job_state``,
  ``status``, ``now_frames``) are sent through a pipe and wait for the child's answer,
  errors included (a round trip of some tens of microseconds). The child answers in
  order, and whoever reads an answer hands it to the call it belongs to: a thread that
  waits, or a coroutine awaiting ``schedule_async``, whose answers the running event
  loop reads as they arrive (:mod:`phantomtouch.engine.pipe`). A plan crosses the pipe
  once: the child keeps the last ``PLAN_CACHE`` plans under a key.
- ``time_at`` and ``frames_at`` read the engine's clock from shared memory, and
  ``contact_move`` writes the newest position into the contact's slot in shared memory,
  which the audio callback reads every block (:mod:`phantomtouch.engine.shared`): no
  message, so a stream of moves costs the caller a few microseconds each.
- ``contact_up`` and ``release_owner`` are checked here and sent without waiting.
- ``stop_all`` raises a mark in shared memory and wakes a thread in the child: it gets
  through even when the pipe is backed up, and voids everything sent before it.
- When this process dies, the pipe closes and the child fades out and exits: nothing
  keeps vibrating after its host is gone.

A sink cannot cross processes, so the child opens the one a :class:`SinkSpec` names.
"""

from __future__ import annotations

import itertools
import multiprocessing
import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any

from phantomtouch.engine.checks import (
    check_frame,
    check_id,
    check_int,
    check_range,
    check_seconds,
)
from phantomtouch.engine.child import serve
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.engine import MAX_VOICES, RENDER_AHEAD_FRAMES
from phantomtouch.engine.jobs import Job, JobState, resolve_plan
from phantomtouch.engine.pipe import RequestPipe
from phantomtouch.engine.shared import MoveSlots, SharedClock
from phantomtouch.engine.soundcard import SinkSpec
from phantomtouch.engine.status import EngineFront, EngineStatus
from phantomtouch.errors import DeviceError, EngineBusyError, ParameterError, ProtocolError
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Carrier, TouchPattern

START_TIMEOUT_S = 60.0
"""Longest wait for the child to import, open its sink and answer."""
CLOSE_TIMEOUT_S = 10.0
PLAN_CACHE = 256
"""Plans the engine process keeps, so that a pattern played again is not sent again."""
REALTIME_PRIORITY = 1
"""SCHED_FIFO priority of the engine process's own threads: the lowest real-time one,
below the audio callback's (JACK gives its clients server priority - 5), above every
ordinary thread, so a thread that holds the interpreter lock the callback waits for is
not preempted by the host's work."""


class ProcessEngine(EngineFront):
    """:class:`~phantomtouch.engine.Engine`'s API, with the engine in a child process.

    Parameters
    ----------
    device : DeviceProfile
    sink : SinkSpec or None
        The sink the child opens; None: ``SinkSpec("default")``.
    queue_capacity, max_voices, contact, log_path, render_ahead_frames
        As for :class:`~phantomtouch.engine.Engine` (the child writes the log).
    realtime_priority : int or None, 1 <= realtime_priority <= 99
        SCHED_FIFO priority of the child's own threads (see ``REALTIME_PRIORITY``);
        None, or no permission for it: ordinary scheduling.

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
    ) -> None:
        if not isinstance(device, DeviceProfile):
            raise ParameterError(f"device={device!r} must be a DeviceProfile")
        if realtime_priority is not None:
            check_int("realtime_priority", realtime_priority, 1, 99)
        spec = sink if sink is not None else SinkSpec()
        self._device = device
        self._lock = threading.Lock()  # the state kept here
        self._down: dict[tuple[str, str], tuple[int, int]] = {}  # slot, generation
        self._clock = SharedClock(device.sample_rate_hz)
        max_contacts = (contact or ContactSettings()).max_contacts
        self._slots = MoveSlots(max_contacts)
        self._plans: OrderedDict[int, tuple[int, Plan]] = OrderedDict()  # id(plan): key, plan
        self._plan_keys = itertools.count(1)
        self._forget: list[int] = []
        context = multiprocessing.get_context("spawn")
        self._mark = context.Value("q", 0, lock=False)
        self._wake = context.Event()
        conn, child_conn = context.Pipe()
        options = {
            "queue_capacity": queue_capacity,
            "max_voices": max_voices,
            "contact": contact,
            "log_path": None if log_path is None else str(log_path),
            "render_ahead_frames": render_ahead_frames,
        }
        self._process = context.Process(
            target=serve,
            args=(
                child_conn,
                device.model_dump_json(),
                spec,
                options,
                self._mark,
                self._wake,
                realtime_priority,
                {"clock": self._clock.raw, "slots": self._slots.raw, "slot_count": max_contacts},
            ),
            name="phantomtouch-engine",
            daemon=True,
        )
        self._process.start()
        child_conn.close()
        if not conn.poll(START_TIMEOUT_S):
            self._process.kill()
            raise DeviceError(f"the engine process did not start within {START_TIMEOUT_S:g} s")
        ok, error = conn.recv()
        if not ok:
            self._process.join(CLOSE_TIMEOUT_S)
            raise error
        self._pipe = RequestPipe(conn)

    @property
    def pid(self) -> int | None:
        """Process id of the engine process."""
        return self._process.pid

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        return self._pipe.call(method, *args, **kwargs)

    def _post(self, method: str, *args: Any, **kwargs: Any) -> None:
        self._pipe.post(method, *args, **kwargs)

    # -- life cycle

    def start(self) -> None:
        """Start the child's sink (see :meth:`Engine.start`)."""
        self._call("start")

    def close(self) -> None:
        """Fade out, close the child's engine and sink, end the child. Idempotent."""
        if not self._pipe.close(CLOSE_TIMEOUT_S):
            return
        self._process.join(CLOSE_TIMEOUT_S)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()

    # -- clock

    @property
    def now_frames(self) -> int:
        return int(self._call("now_frames"))

    def server_time_s(self) -> float:
        """The server clock, s (``time.monotonic()``, the same in both processes)."""
        return time.monotonic()

    def frames_at(self, server_time_s: float) -> int:
        """See :meth:`Engine.frames_at` (the clock is read from shared memory)."""
        return self._clock.frames_at(check_seconds("server_time_s", server_time_s))

    def time_at(self, frame: int) -> float:
        """See :meth:`Engine.time_at` (the clock is read from shared memory)."""
        return self._clock.time_at(check_int("frame", frame, -(1 << 62), 1 << 62))

    # -- jobs

    def schedule(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
    ) -> Job:
        """See :meth:`Engine.schedule`; the pattern is planned here, not in the child."""
        resolved, request = self._schedule_request(pattern)
        try:
            job: Job = self._call("schedule", *request, start_frame=start_frame, owner=owner)
        except BaseException:
            self._schedule_failed(resolved, request)
            raise
        return job

    async def schedule_async(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
    ) -> Job:
        """:meth:`schedule` for a coroutine: the event loop goes on while the child works.

        The answer is read by the running loop when it arrives, so a server can accept the
        next request while the engine process schedules this one.
        """
        resolved, request = self._schedule_request(pattern)
        try:
            job: Job = await self._pipe.call_async(
                "schedule", *request, start_frame=start_frame, owner=owner
            )
        except BaseException:
            self._schedule_failed(resolved, request)
            raise
        return job

    def _schedule_request(self, pattern: TouchPattern | Plan) -> tuple[Plan, tuple[Any, ...]]:
        """The plan, and the child's arguments: its key, the plan unless sent already,
        and the keys of plans the child may forget."""
        resolved = resolve_plan(pattern, self._device)
        with self._lock:
            known = self._plans.get(id(resolved))
            if known is not None and known[1] is resolved:
                self._plans.move_to_end(id(resolved))
                key, sent = known[0], None
            else:
                key, sent = next(self._plan_keys), resolved
                self._plans[id(resolved)] = (key, resolved)
                while len(self._plans) > PLAN_CACHE:
                    self._forget.append(self._plans.popitem(last=False)[1][0])
            forget, self._forget = self._forget, []
        return resolved, (key, sent, forget)

    def _schedule_failed(self, resolved: Plan, request: tuple[Any, ...]) -> None:
        key, sent, forget = request
        with self._lock:
            self._forget.extend(forget)  # the child may not have seen them
            if sent is not None:  # nor this plan: send it again next time
                self._plans.pop(id(resolved), None)
                self._forget.append(key)

    def job_state(self, job_id: str) -> JobState | None:
        return self._call("job_state", job_id)

    def stop(self, job_id: str) -> bool:
        return bool(self._call("stop", job_id))

    def stop_all(self) -> None:
        """See :meth:`Engine.stop_all`; never waits for the child."""
        if not self._pipe.raise_mark(self._mark):
            return  # closed
        with self._lock:
            for slot, _ in self._down.values():
                self._slots.release(slot)
            self._down.clear()
        self._wake.set()

    # -- contacts

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
        """See :meth:`Engine.contact_down`; the contact gets a slot for its moves."""
        key = (owner, contact)
        with self._lock:
            held = self._down.pop(key, None)
            slot = held[0] if held is not None else None
            fresh = self._slots.allocate() if slot is None else (slot, self._slots.renew())
            if fresh is None:
                raise EngineBusyError(
                    f"{len(self._down)} contacts are down; at most "
                    f"max_contacts={self._slots.capacity}"
                )
        try:
            self._call(
                "contact_down",
                owner,
                contact,
                x_cm,
                y_cm,
                intensity=intensity,
                carrier=carrier,
                law=law,
                normal_velocity_m_s=normal_velocity_m_s,
                at_frame=at_frame,
                slot=fresh,
            )
        except BaseException:
            with self._lock:
                if held is not None:  # the contact that was down stays down
                    self._down[key] = held
                else:
                    self._slots.release(fresh[0])
            raise
        with self._lock:
            self._down[key] = fresh

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
        """See :meth:`Engine.contact_move`; checked here, written into the contact's slot."""
        check_id("owner", owner)
        check_id("contact", contact)
        check_range("x_cm", x_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm")
        check_range("y_cm", y_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm")
        if intensity is not None:
            check_range("intensity", intensity, 0.0, 1.0, "(1 = safety.max_level_db)")
        frame = check_frame("at_frame", at_frame)
        with self._lock:
            held = self._down.get((owner, contact))
            if held is None:
                raise ProtocolError(
                    f"contact={contact!r} of owner={owner!r} is not down: expected down, got move"
                )
            self._slots.write(held[0], held[1], float(x_cm), float(y_cm), intensity, frame)

    def contact_up(
        self,
        owner: str,
        contact: str,
        *,
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """See :meth:`Engine.contact_up`; checked here, sent without waiting."""
        check_id("owner", owner)
        check_id("contact", contact)
        if normal_velocity_m_s is not None:
            check_range("normal_velocity_m_s", normal_velocity_m_s, -10.0, 10.0, "m/s")
        check_frame("at_frame", at_frame)
        with self._lock:
            held = self._down.pop((owner, contact), None)
            if held is not None:
                self._slots.release(held[0])
        self._post(
            "contact_up", owner, contact, normal_velocity_m_s=normal_velocity_m_s, at_frame=at_frame
        )

    def release_owner(self, owner: str) -> None:
        """See :meth:`Engine.release_owner`; sent without waiting."""
        with self._lock:
            for key in [key for key in self._down if key[0] == owner]:
                self._slots.release(self._down.pop(key)[0])
        self._post("release_owner", owner)

    def status(self) -> EngineStatus:
        return self._call("status")
