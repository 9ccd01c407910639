"""Starting an engine process (:func:`spawn`), and what the host shares with it
(:class:`ChildProcess`). Host, non real time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import threading
from multiprocessing.connection import wait
from typing import Any

import numpy as np

from phantomtouch.engine.child import serve
from phantomtouch.engine.link import Outbox
from phantomtouch.engine.scheduler import RENDER_TIMES
from phantomtouch.engine.shared import MoveSlots, SharedClock, StatusBlock
from phantomtouch.engine.soundcard import SinkSpec
from phantomtouch.errors import DeviceError
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import PolylinePath

START_TIMEOUT_S = 60.0
"""Longest wait for the child to import, open its sink and answer."""
CLOSE_TIMEOUT_S = 10.0

_BLANK_PATH = PolylinePath(points_cm=[(0.0, 0.0)])


def slim(plan: Plan) -> Plan:
    """The plan without what the engine process has already: device, geometry, and the
    pattern's path (the timelines carry the resolved path)."""
    pattern = plan.pattern.model_copy(update={"path": _BLANK_PATH})
    return dataclasses.replace(plan, pattern=pattern, device=None, geometry=None)  # type: ignore[arg-type]


@dataclasses.dataclass
class ChildProcess:
    """One engine process and what is shared with it (host)."""

    process: Any
    outbox: Outbox
    reports: Any
    """The read end of the reports' pipe (a ``multiprocessing.connection.Connection``)."""
    clock: SharedClock
    slots: MoveSlots
    status: StatusBlock
    mark: Any
    loads: np.ndarray
    """The audio callback's render loads (see :class:`~phantomtouch.engine.scheduler.Scheduler`)."""
    costs: tuple[float, float, float]
    backend: str
    output_device: str | None
    reader: threading.Thread | None = None

    def end(self, *, kill: bool) -> None:
        """End the process (killed with ``kill``), its outbox and its reader."""
        if kill:
            with contextlib.suppress(OSError, ValueError):
                self.process.kill()
        self.process.join(CLOSE_TIMEOUT_S)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.outbox.close(0.1)
        if self.reader is not None:
            self.reader.join(1.0)
        self.reports.close()


def spawn(
    device: DeviceProfile,
    spec: SinkSpec,
    options: dict[str, Any],
    priority: int | None,
    timeout_s: float = START_TIMEOUT_S,
) -> ChildProcess:
    """Start an engine process and wait for its first report (ready, or the error).

    Raises
    ------
    DeviceError
        It did not start within ``timeout_s``, or ended while starting; or the error it
        reported (its sink could not open).
    """
    context = multiprocessing.get_context("spawn")
    clock = SharedClock(device.sample_rate_hz)
    slots = MoveSlots(options["contact_slots"])
    status = StatusBlock(device.channels)
    mark = context.Value("q", 0, lock=False)
    loads = context.RawArray("d", RENDER_TIMES)
    commands_in, commands_out = context.Pipe(duplex=False)
    reports_in, reports_out = context.Pipe(duplex=False)
    process = context.Process(
        target=serve,
        args=(
            commands_in,
            reports_out,
            device.model_dump_json(),
            spec,
            options,
            mark,
            priority,
            {
                "clock": clock.raw,
                "slots": slots.raw,
                "status": status.raw,
                "loads": loads,
            },
        ),
        name="phantomtouch-engine",
        daemon=True,
    )
    process.start()
    commands_in.close()
    reports_out.close()
    try:
        ready = _first_report(reports_in, process, timeout_s)
    except BaseException:
        reports_in.close()
        commands_out.close()
        process.kill()
        process.join(CLOSE_TIMEOUT_S)
        raise
    return ChildProcess(
        process=process,
        outbox=Outbox(commands_out),
        reports=reports_in,
        clock=clock,
        slots=slots,
        status=status,
        mark=mark,
        loads=np.frombuffer(loads, dtype=np.float64),
        costs=(float(ready[1][0]), float(ready[1][1]), float(ready[1][2])),
        backend=str(ready[2]),
        output_device=ready[3],
    )


def _first_report(reports: Any, process: Any, timeout_s: float) -> Any:
    """Wait for the pipe or the process's end (``multiprocessing.connection.wait``: Windows'
    ``select`` takes sockets only), then read the first report."""
    if not wait([reports, process.sentinel], timeout_s):
        raise DeviceError(f"the engine process did not start within {timeout_s:g} s")
    try:
        message = reports.recv()
    except (EOFError, OSError):
        raise DeviceError("the engine process ended while starting") from None
    if message[0] == "failed":
        raise message[1]
    return message
