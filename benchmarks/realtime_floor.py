"""The machine's own real-time floor, measured beside the service by ``cyclictest``.

``cyclictest`` (Debian ``rt-tests``) runs one thread per core at SCHED_FIFO priority 80
(above JACK and the engine) that only sleeps until its next period and notes how late it
woke. It does no audio work, so its late wake-ups are what the machine — the kernel, a
hypervisor, the other programs — imposes on any real-time thread, whatever the engine
does: a thread woken more than one period late has missed its period, and so would any
audio callback scheduled then. An audio callback misses sooner: it must also do its work
and hand the block back before the period ends, so a stall of well under a period is
enough. :func:`in_stalls` therefore sets each of JACK's xruns beside the probe's own
record of that moment: an xrun during which the probe, too, woke at least half a period
late is the machine's. :func:`xrun_causes` tells JACK's own xruns apart from what
``jackd`` printed, and :func:`floor` measures both with JACK alone.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import signal
import subprocess
import threading
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tests.support.jack import JackServer, JackXrunCounter


STALL_WINDOW_S = (0.015, 0.005)
"""An xrun falls in a stall the probe saw when a wake-up at least half a period late
overlaps the 15 ms before JACK reported it or the 5 ms after (the report comes from
JACK's notification thread, a little after the cycle that overran)."""

VERBOSE_LINE = re.compile(r"^\s*(\d+):\s*(\d+):\s*(\d+)\s*$")
"""``cyclictest -v``: ``thread: cycle: latency_us``, one line per wake-up."""


class LatencyProbe:
    """``cyclictest -m -q -p 80 -t CORES -a -i PERIOD -d 0 -v`` while a scenario runs.

    Every wake-up's latency is read as it comes, with when it was due, so that each of
    JACK's xruns can be set beside what the probe saw at that moment
    (:func:`in_stalls`).

    Parameters
    ----------
    period_us : int
        The wake-up interval: wake-ups at least this late are late (a missed period).
    """

    def __init__(self, period_us: int) -> None:
        self.period_us = int(period_us)
        self.process: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None
        self._samples: list[tuple[int, int, int]] = []
        self._starts: dict[int, float] = {}
        self._other: list[str] = []

    @staticmethod
    def available() -> bool:
        return shutil.which("cyclictest") is not None and shutil.which("stdbuf") is not None

    def start(self) -> LatencyProbe:
        executable, stdbuf = shutil.which("cyclictest"), shutil.which("stdbuf")
        if executable is None or stdbuf is None:
            raise RuntimeError("cyclictest or stdbuf not found (Debian rt-tests, coreutils)")
        cores = os.cpu_count() or 1
        period = str(self.period_us)
        command = [stdbuf, "-oL", executable, "-m", "-q", "-p", "80", "-t", str(cores), "-a"]
        command += ["-i", period, "-d", "0", "-v"]
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1
        )
        self._reader = threading.Thread(target=self._read, args=(self.process,), daemon=True)
        self._reader.start()
        return self

    def _read(self, process: subprocess.Popen[str]) -> None:
        """Keep each wake-up; estimate when each thread's cycle 0 was due (the earliest
        arrival of a line less its cycles and latency: a line is read after its wake-up)."""
        assert process.stdout is not None
        period_s = self.period_us / 1e6
        for line in process.stdout:
            arrived_s = time.monotonic()
            match = VERBOSE_LINE.match(line)
            if match is None:
                self._other.append(line)
                continue
            thread, cycle, latency_us = (int(group) for group in match.groups())
            self._samples.append((thread, cycle, latency_us))
            due_s = arrived_s - cycle * period_s - latency_us / 1e6
            self._starts[thread] = min(self._starts.get(thread, due_s), due_s)

    def stop(self) -> dict[str, Any]:
        """Stop it; ``wakeups``, ``late_wakeups`` (at least one period late),
        ``max_latency_us``, and ``stalls``: ``[due_s, latency_us]`` (``time.monotonic()``
        when it was due) of each wake-up at least half a period late."""
        process, self.process = self.process, None
        if process is None or self._reader is None:
            raise RuntimeError("the probe was not started")
        process.send_signal(signal.SIGINT)
        process.wait(timeout=10)
        self._reader.join(timeout=10)
        if not self._samples:
            raise RuntimeError(f"cyclictest printed no wake-up:\n{''.join(self._other)[-2000:]}")
        period_s = self.period_us / 1e6
        latencies = [latency for _, _, latency in self._samples]
        return {
            "wakeups": len(latencies),
            "late_wakeups": sum(latency >= self.period_us for latency in latencies),
            "max_latency_us": max(latencies),
            "stalls": [
                [self._starts[thread] + cycle * period_s, latency]
                for thread, cycle, latency in self._samples
                if 2 * latency >= self.period_us
            ],
        }


def in_stalls(
    xrun_times_s: list[float],
    stalls: list[list[float]],
    seconds: float,
    kinds: list[str] | None = None,
) -> dict[str, Any]:
    """How many xruns fall in a stall the probe saw (:data:`STALL_WINDOW_S`), how many
    would by chance (the share of the scenario's ``seconds`` such windows cover, times the
    xruns), and how many are beyond the machine.

    Parameters
    ----------
    xrun_times_s : list of float
        ``time.monotonic()`` of each xrun JACK reported, in order.
    stalls : list of [due_s, latency_us]
        As :meth:`LatencyProbe.stop` returns.
    seconds : float, > 0
    kinds : list of str, optional
        Each xrun's cause in the same order (:func:`xrun_kinds`). When given for every
        xrun, an xrun of the dummy driver's own late timer (``late_wakeup``: no client
        was slow) is the machine's too.

    Returns
    -------
    dict
        ``xruns``, ``in_stalls``, ``by_chance``, ``stall_share`` and ``beyond_machine``:
        the xruns neither in a stall nor (with ``kinds``) a late wake-up of JACK's timer.
    """
    before_s, after_s = STALL_WINDOW_S
    spans = sorted((due - after_s, due + latency / 1e6 + before_s) for due, latency in stalls)
    covered_s, reach_s = 0.0, -math.inf
    for begin, end in spans:
        covered_s += max(0.0, end - max(begin, reach_s))
        reach_s = max(reach_s, end)
    inside = [any(begin <= x <= end for begin, end in spans) for x in xrun_times_s]
    if kinds is None or len(kinds) != len(inside):
        kinds = ["slow_cycle"] * len(inside)
    share = min(1.0, covered_s / seconds)
    return {
        "xruns": len(inside),
        "in_stalls": sum(inside),
        "by_chance": share * len(inside),
        "stall_share": share,
        "beyond_machine": sum(
            not seen and kind != "late_wakeup" for seen, kind in zip(inside, kinds, strict=True)
        ),
    }


def xrun_kinds(log: str, period_us: float) -> list[str]:
    """Each xrun the dummy driver reported, in order: ``late_wakeup`` or ``slow_cycle``
    (:func:`xrun_causes`)."""
    return [
        "late_wakeup" if int(usec) < period_us / 2 else "slow_cycle"
        for usec in re.findall(r"JackTimedDriver::Process XRun = (\d+) usec", log)
    ]


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
    for kind in xrun_kinds(log, period_us):
        causes[kind] += 1
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
    machine = probe.stop()
    log = jack.output()[log_before:]
    machine["xruns_in_stalls"] = in_stalls(
        xruns.times[xruns_before:], machine["stalls"], seconds, xrun_kinds(log, period_us)
    )
    return {
        "seconds": seconds,
        "jack_xruns": xruns.xruns - xruns_before,
        "jack_xrun_causes": xrun_causes(log, period_us),
        "machine_floor": machine,
    }
