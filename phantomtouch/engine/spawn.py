"""Starting an engine process and what the host shares with it (:class:`ChildProcess`).
Host, non real time.
"""

from __future__ import annotations

import contextlib
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
from phantomtouch.errors import DeviceError
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.schema.device import DeviceProfile

START_TIMEOUT_S = 60.0
"""Longest wait for the child to import, open its sink and answer."""
CLOSE_TIMEOUT_S = 10.0


class ChildProcess:
    """An engine process, started and ready, and what the host shares with it: the
    ``outbox`` of its commands, its ``reports`` (read by a thread that runs
    ``read_reports(child)``), and in shared memory its ``clock``, move ``slots``,
    ``status``, stop ``mark``, render ``loads`` and callback ``seconds``; and what its
    sink found at start: ``block_frames``, ``period_frames`` and ``period_source``
    (:class:`~phantomtouch.output.sinks.Sink`). Host.

    Parameters
    ----------
    device, spec, options, priority
        What :func:`~phantomtouch.engine.child.serve` plays with.
    read_reports : callable
    timeout_s : float
        Longest wait for the first report.

    Raises
    ------
    DeviceError
        It did not start within ``timeout_s``, or ended while starting; or the error it
        reported (its sink could not open).
    """

    def __init__(
        self,
        device: DeviceProfile,
        spec: SinkSpec,
        options: dict[str, Any],
        priority: int | None,
        read_reports: Callable[[ChildProcess], None],
        timeout_s: float,
    ) -> None:
        context = multiprocessing.get_context("spawn")
        self.clock = SharedClock(device.sample_rate_hz)
        self.slots = MoveSlots(options["contact"].max_contacts, device.channels)
        self.status = StatusBlock(device.channels)
        self.mark = context.Value("q", 0, lock=False)
        loads = context.RawArray("d", RENDER_TIMES)
        self.loads = np.frombuffer(loads, dtype=np.float64)
        seconds = context.RawArray("d", RENDER_TIMES)
        self.seconds = np.frombuffer(seconds, dtype=np.float64)
        raw = dict(
            clock=self.clock.raw,
            slots=self.slots.raw,
            status=self.status.raw,
            loads=loads,
            seconds=seconds,
        )
        commands_in, commands_out = context.Pipe(duplex=False)
        self.reports, reports_out = context.Pipe(duplex=False)
        device_json = device.model_dump_json()
        self.process = context.Process(
            target=serve,
            args=(commands_in, reports_out, device_json, spec, options, self.mark, priority, raw),
            name="phantomtouch-engine",
            daemon=True,
        )
        self.process.start()
        commands_in.close()
        reports_out.close()
        try:  # connection.wait, not select: Windows' select takes sockets only
            if not wait([self.reports, self.process.sentinel], timeout_s):
                raise DeviceError(f"the engine process did not start within {timeout_s:g} s")
            try:
                ready = self.reports.recv()
            except (EOFError, OSError):
                raise DeviceError("the engine process ended while starting") from None
            if ready[0] == "failed":
                raise ready[1]
        except BaseException:
            self.reports.close()
            commands_out.close()
            self.process.kill()
            self.process.join(CLOSE_TIMEOUT_S)
            raise
        self.outbox = Outbox(commands_out)
        self.costs = (float(ready[1][0]), float(ready[1][1]), float(ready[1][2]))
        self.backend = str(ready[2])
        self.output_device: str | None = ready[3]
        self.block_frames, self.period_frames, self.period_source = ready[4]
        self.reader = threading.Thread(
            target=read_reports, args=(self,), name="phantomtouch-reports", daemon=True
        )
        self.reader.start()

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
