"""The engine process's side of :class:`~phantomtouch.engine.process.ProcessEngine`.

:func:`serve` runs in the child: it opens the sink a
:class:`~phantomtouch.engine.soundcard.SinkSpec` names, builds a real
:class:`~phantomtouch.engine.Engine` and answers the host's calls from the pipe, one at a
time. Messages the host sent without waiting for an answer and before its last
``stop_all`` are dropped; a thread applies ``stop_all`` as soon as the host raises its
mark. Plans arrive once and are kept under the host's key; contact moves and the clock
go through shared memory (:mod:`phantomtouch.engine.shared`). When the pipe closes (the
host is gone), the engine fades out and the child ends.
"""

from __future__ import annotations

import gc
import logging
import os
import sys
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.engine import Engine
from phantomtouch.engine.jobs import Job
from phantomtouch.engine.shared import MoveSlots, SharedClock
from phantomtouch.engine.sinks import CaptureSink
from phantomtouch.engine.soundcard import SinkSpec
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger(__name__)

SWITCH_INTERVAL_S = 0.001
"""How soon a thread of the engine process that holds the interpreter lock is asked to
hand it over, s (Python's default, 5 ms, is longer than a block of 128 frames): the
audio callback waits at most about this long for the lock."""


class _Child:
    """The engine process: a real Engine served over a pipe."""

    def __init__(
        self, conn: Connection, engine: Engine, spec: SinkSpec, mark: Any, slots: MoveSlots
    ) -> None:
        self.conn = conn
        self.engine = engine
        self.spec = spec
        self.mark = mark
        self.slots = slots
        self.handled_mark = 0
        self.stop_lock = threading.Lock()
        self.plans: dict[int, Plan] = {}
        self.handlers: dict[str, Callable[..., Any]] = {
            "schedule": self.schedule,
            "contact_down": self.contact_down,
            "contact_up": self.contact_up,
            "release_owner": self.release_owner,
        }

    def apply_stop_all(self) -> None:
        with self.stop_lock:
            mark = self.mark.value
            if mark > self.handled_mark:
                self.handled_mark = mark
                self.engine.stop_all()
                self.slots.unbind_all()

    def schedule(self, plan_key: int, plan: Plan | None, forget: list[int], **kwargs: Any) -> Job:
        """``Engine.schedule`` with the plan sent once and kept under its key."""
        for key in forget:
            self.plans.pop(key, None)
        if plan is not None:
            self.plans[plan_key] = plan
        return self.engine.schedule(self.plans[plan_key], **kwargs)

    def contact_down(self, *args: Any, slot: tuple[int, int], **kwargs: Any) -> None:
        """``Engine.contact_down``, then the contact's moves come through its slot."""
        self.engine.contact_down(*args, **kwargs)
        owner, contact = args[0], args[1]
        self.slots.bind(slot[0], slot[1], owner, contact)

    def contact_up(self, owner: str, contact: str, **kwargs: Any) -> None:
        self.slots.unbind(owner, contact)
        self.engine.contact_up(owner, contact, **kwargs)

    def release_owner(self, owner: str) -> None:
        self.slots.unbind(owner)
        self.engine.release_owner(owner)

    def watch_stop_all(self, wake: Any) -> None:
        while True:
            wake.wait()
            wake.clear()
            self.apply_stop_all()

    def serve(self) -> None:
        while True:
            try:
                seq, method, args, kwargs, answer = self.conn.recv()
            except (EOFError, OSError):  # the host is gone: fade out and leave
                self.close()
                return
            self.apply_stop_all()
            if method == "close":
                self.close()
                self.conn.send((True, None))
                return
            if not answer and seq < self.handled_mark:
                continue  # sent before a stop_all: void
            try:
                attribute = self.handlers.get(method) or getattr(self.engine, method)
                result = attribute(*args, **kwargs) if callable(attribute) else attribute
                reply = (True, result)
            except Exception as exc:
                if not answer:
                    logger.warning("engine process: %s failed: %s", method, exc)
                    continue
                reply = (False, exc)
            if answer:
                self.conn.send(reply)

    def close(self) -> None:
        self.engine.close()
        sink = self.engine.sink
        if isinstance(sink, CaptureSink) and self.spec.wav_path is not None:
            sink.write_wav(self.spec.wav_path)


def raise_priority(priority: int | None) -> None:
    """Run this thread, and the threads it starts, with SCHED_FIFO ``priority``."""
    if priority is None or not hasattr(os, "sched_setscheduler"):
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        logger.info("engine process keeps normal priority: %s", exc)


def serve(
    conn: Connection,
    device_json: str,
    spec: SinkSpec,
    options: dict[str, Any],
    mark: Any,
    wake: Any,
    priority: int | None,
    shared: dict[str, Any],
) -> None:
    """The engine process's main function (the target of the child process).

    Parameters
    ----------
    conn : Connection
        The pipe to the host: requests ``(seq, method, args, kwargs, answer)`` in, answers
        ``(ok, result or exception)`` out.
    device_json : str
        The device profile as JSON.
    spec : SinkSpec
    options : dict
        Keyword arguments of :class:`~phantomtouch.engine.Engine`.
    mark : multiprocessing.Value
        Sequence number of the host's last ``stop_all``.
    wake : multiprocessing.Event
        Set by the host with every ``stop_all``.
    priority : int or None
        SCHED_FIFO priority for this process's threads.
    shared : dict
        The shared memory: ``clock`` (a :class:`~phantomtouch.engine.shared.SharedClock`'s
        array), ``slots`` and ``slot_count`` (:class:`~phantomtouch.engine.shared.MoveSlots`).
    """
    raise_priority(priority)
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    try:
        device = DeviceProfile.model_validate_json(device_json)
        clock = SampleClock(
            device.sample_rate_hz,
            publish=SharedClock(device.sample_rate_hz, shared["clock"]).publish,
        )
        slots = MoveSlots(shared["slot_count"], shared["slots"])
        engine = Engine(device, spec.open(device), clock=clock, **options)
        engine.take_positions(slots)
    except Exception as exc:
        conn.send((False, exc))
        return
    gc.freeze()  # what start-up made is never scanned again: collections stay short
    conn.send((True, None))
    child = _Child(conn, engine, spec, mark, slots)
    threading.Thread(target=child.watch_stop_all, args=(wake,), daemon=True).start()
    child.serve()
