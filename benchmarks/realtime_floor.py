"""The machine's own real-time floor, measured beside the service by ``cyclictest``.

``cyclictest`` (Debian ``rt-tests``) runs one thread per core at SCHED_FIFO priority 80
(above JACK and the engine) that only sleeps until its next period and notes how late it
woke. It does no audio work, so its late wake-ups are what the machine — the kernel, a
hypervisor, the other programs — imposes on any real-time thread, whatever the engine
does: a thread woken more than one period late has missed its period, and so would any
audio callback scheduled then. :func:`xrun_causes` tells JACK's own xruns apart from what
``jackd`` printed, and :func:`floor` measures both with JACK alone.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tests.support.jack import JackServer, JackXrunCounter


class LatencyProbe:
    """``cyclictest -m -q -p 80 -t CORES -a -i PERIOD -h PERIOD`` while a scenario runs.

    Parameters
    ----------
    period_us : int
        The wake-up interval and the histogram's width: wake-ups at least this late are
        the histogram's overflows.
    """

    def __init__(self, period_us: int) -> None:
        self.period_us = int(period_us)
        self.process: subprocess.Popen[str] | None = None

    @staticmethod
    def available() -> bool:
        return shutil.which("cyclictest") is not None

    def start(self) -> LatencyProbe:
        executable = shutil.which("cyclictest")
        if executable is None:
            raise RuntimeError("cyclictest not found (Debian package rt-tests)")
        cores = os.cpu_count() or 1
        period = str(self.period_us)
        command = [executable, "-m", "-q", "-p", "80", "-t", str(cores), "-a"]
        command += ["-i", period, "-h", period]
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        return self

    def stop(self) -> dict[str, Any]:
        """Stop it; ``wakeups``, ``late_wakeups`` (at least one period late) and
        ``max_latency_us``, over all its threads."""
        process, self.process = self.process, None
        if process is None:
            raise RuntimeError("the probe was not started")
        process.send_signal(signal.SIGINT)  # cyclictest prints its histogram and ends
        output, _ = process.communicate(timeout=10)
        return parse(output)


def numbers(output: str, label: str) -> list[int]:
    match = re.search(rf"^# {label}:((?: +\d+)+)\s*$", output, re.MULTILINE)
    if match is None:
        raise RuntimeError(f"cyclictest printed no '{label}' line:\n{output[-2000:]}")
    return [int(value) for value in match.group(1).split()]


def parse(output: str) -> dict[str, Any]:
    """The figures of a ``cyclictest -h`` run's summary."""
    return {
        "wakeups": sum(numbers(output, "Total")),
        "late_wakeups": sum(numbers(output, "Histogram Overflows")),
        "max_latency_us": max(numbers(output, "Max Latencies")),
    }


def xrun_causes(log: str, period_us: float) -> dict[str, int]:
    """JACK's xruns by cause, from what ``jackd`` printed.

    The dummy driver reports ``JackTimedDriver::Process XRun = N usec`` when a cycle ends
    after the next one should have begun, N being how long the cycle's processing took
    (in sync mode, waiting for every client). ``late_wakeup``: N under half a period —
    the cycle itself was short, so the driver's timer woke late (the machine's timer; it
    happens with no client connected). ``slow_cycle``: N of half a period or more — the
    graph, that is a client, took that long. ``client_late:NAME``: JACK named a client that
    had not finished its cycle in time.
    """
    causes: dict[str, int] = {"late_wakeup": 0, "slow_cycle": 0}
    for usec in re.findall(r"JackTimedDriver::Process XRun = (\d+) usec", log):
        causes["late_wakeup" if int(usec) < period_us / 2 else "slow_cycle"] += 1
    late = re.findall(r"client = (\S+) was not finished|client (\S+) finished after current", log)
    for names in late:
        key = f"client_late:{names[0] or names[1]}"
        causes[key] = causes.get(key, 0) + 1
    return causes


def floor(
    jack: JackServer, xruns: JackXrunCounter, seconds: float, period_us: float
) -> dict[str, Any]:
    """JACK's xruns with no client of ours in its graph: what the machine gives anyway."""
    log_before, xruns_before = len(jack.output()), xruns.xruns
    probe = LatencyProbe(round(period_us)).start()
    time.sleep(seconds)
    return {
        "seconds": seconds,
        "jack_xruns": xruns.xruns - xruns_before,
        "jack_xrun_causes": xrun_causes(jack.output()[log_before:], period_us),
        "machine_floor": probe.stop(),
    }
