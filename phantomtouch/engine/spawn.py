"""Starting an engine process (:func:`spawn`), and what the host shares with it
(:class:`ChildProcess`). Host, non real time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import threading
from collections.abc import Callable
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
    reader: threading.Thread = dataclasses.field(init=False)

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
        self.reader.join(1.0)
        self.reports.close()


def spawn(
    device: DeviceProfile,
    spec: SinkSpec,
    options: dict[str, Any],
    priority: int | None,
    read_reports: Callable[[ChildProcess], None],
    timeout_s: float,
) -> ChildProcess:
    """Start an engine process, wait for its first report (ready, or the error), then
    start a thread that runs ``read_reports(child)``.

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
    device_json = device.model_dump_json()
    shared = {"clock": clock.raw, "slots": slots.raw, "status": status.raw, "loads": loads}
    commands_in, commands_out = context.Pipe(duplex=False)
    reports_in, reports_out = context.Pipe(duplex=False)
    process = context.Process(
        target=serve,
        args=(commands_in, reports_out, device_json, spec, options, mark, priority, shared),
        name="phantomtouch-engine",
        daemon=True,
    )
    process.start()
    commands_in.close()
    reports_out.close()
    try:  # connection.wait, not select: Windows' select takes sockets only
        if not wait([reports_in, process.sentinel], timeout_s):
            raise DeviceError(f"the engine process did not start within {timeout_s:g} s")
        try:
            ready = reports_in.recv()
        except (EOFError, OSError):
            raise DeviceError("the engine process ended while starting") from None
        if ready[0] == "failed":
            raise ready[1]
    except BaseException:
        reports_in.close()
        commands_out.close()
        process.kill()
        process.join(CLOSE_TIMEOUT_S)
        raise
    child = ChildProcess(
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
    child.reader = threading.Thread(
        target=read_reports, args=(child,), name="phantomtouch-reports", daemon=True
    )
    child.reader.start()
    return child
