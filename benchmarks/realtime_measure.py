"""One scenario of ``bench_realtime.py`` measured: its load run beside the probes.

:func:`measure` rests the service, then runs a :data:`Load` while it samples ``/health``
and ``/metrics`` (``realtime_http.py``), runs the ``cyclictest`` probe
(``realtime_floor.py``), counts JACK's xruns and the CPU time spent
(``realtime_usage.py``), and draws the scenario's figures from what it saw: counter
deltas, the highest samples, latency quantiles in ms.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from realtime_floor import LatencyProbe, in_stalls, xrun_causes, xrun_kinds
from realtime_http import HttpConnection, metrics, sample_health, sample_metrics, timed_request
from realtime_usage import cpu_seconds
from yardstick import block_copy_s

if TYPE_CHECKING:
    from tests.support.jack import JackServer, JackXrunCounter

TAIL_S = 0.5
"""After the load, the engine's counters are read once more this much later."""

Load = Callable[[float], Awaitable[dict[str, Any]]]
"""A load: given the deadline (monotonic clock), what it did."""


def percentile(values: list[float], q: float) -> float | None:
    """The ``q`` quantile (nearest rank) of ``values``; None without values."""
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def ms(seconds: float | None) -> float | None:
    return None if seconds is None else seconds * 1e3


def counter_delta(before: dict[str, int], after: dict[str, int]) -> dict[str, int]:
    keys = sorted(set(before) | set(after))
    return {
        k: after.get(k, 0) - before.get(k, 0) for k in keys if after.get(k, 0) > before.get(k, 0)
    }


def highest(samples: list[dict[str, Any]], key: str) -> float | None:
    values = [s[key] for s in samples if s[key] is not None]
    return max(values) if values else None


def callback_us(samples: list[dict[str, Any]]) -> dict[str, float | None]:
    """The audio callback's own time, µs, from ``/metrics`` sampled during a scenario: the
    median of the sampled medians, and the highest p99 and largest (None: a service that
    does not report ``phantomtouch_callback_seconds``)."""
    medians = [s["callback_p50_s"] for s in samples if s["callback_p50_s"] is not None]
    p99, largest = highest(samples, "callback_p99_s"), highest(samples, "callback_max_s")
    return {
        "callback_p50_us": float(np.median(medians)) * 1e6 if medians else None,
        "callback_p99_us": None if p99 is None else p99 * 1e6,
        "callback_max_us": None if largest is None else largest * 1e6,
    }


async def rest(port: int, seconds: float) -> list[float]:
    """``POST /stop``, wait (10 s at most) until no voice plays, then ``seconds`` more,
    timing the yardstick meanwhile (:func:`copies_while_resting`, µs)."""
    connection = HttpConnection(port)
    try:
        await timed_request(connection, "POST", "/stop")
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            figures = await metrics(connection)
            if figures is None or not figures["active_voices"]:
                break
            await asyncio.sleep(0.1)
    finally:
        connection.close()
    return await copies_while_resting(seconds)


async def copies_while_resting(seconds: float) -> list[float]:
    """Wait ``seconds``, timing the yardstick's copy (300 timings, a few milliseconds) once a
    second meanwhile, µs. The machine's speed can change twofold from one second to the next
    (``yardstick.py``), so each scenario is set beside the copies of its own rest."""
    copies_us: list[float] = []
    deadline = time.monotonic() + seconds
    while (left_s := deadline - time.monotonic()) > 0.0:
        await asyncio.sleep(min(1.0, left_s))
        copies_us.append(block_copy_s(timings=300) * 1e6)
    return copies_us


async def measure(
    port: int,
    xruns: JackXrunCounter,
    jack: JackServer,
    seconds: float,
    make_load: Load,
    args: argparse.Namespace,
) -> dict[str, Any]:
    """Rest, then run ``make_load`` for ``seconds`` while sampling ``/health`` and ``/metrics``.

    The period the probe and JACK's xruns are judged by is ``jack``'s; ``args`` gives the
    rest (``rest_seconds``) and the ``/health`` rate (``health_hz``).
    """
    period_us = jack.period_frames / jack.sample_rate_hz * 1e6
    copies_us = await rest(port, args.rest_seconds)
    connection = HttpConnection(port)
    try:
        before = await metrics(connection)
        xruns_before = xruns.xruns
        log_before = len(jack.output())
        probe = LatencyProbe(round(period_us)).start()
        cpu_before = cpu_seconds()
        started = time.monotonic()
        deadline = started + seconds
        done, health, samples = await asyncio.gather(
            make_load(deadline),
            sample_health(port, deadline, 1.0 / args.health_hz),
            sample_metrics(port, deadline, 1.0),
        )
        elapsed_s = time.monotonic() - started
        cpu_after = cpu_seconds()
        machine = probe.stop()
        await asyncio.sleep(TAIL_S)
        after = await metrics(connection)
        xruns_after = xruns.xruns
        log_during = jack.output()[log_before:]
        machine["xruns_in_stalls"] = in_stalls(
            xruns.times[xruns_before:xruns_after],
            machine["stalls"],
            elapsed_s + TAIL_S,
            xrun_kinds(log_during, period_us),
        )
    finally:
        connection.close()
    if before is None or after is None:
        raise RuntimeError("the service did not answer GET /metrics around the scenario")
    samples.append(after)
    latencies = health["latencies_s"]
    underruns, inline_renders = (
        None if before[key] is None or after[key] is None else int(after[key] - before[key])
        for key in ("underruns", "inline_renders")
    )
    machine_s, ours_s = (end - start for start, end in zip(cpu_before, cpu_after, strict=True))
    return {
        "seconds": elapsed_s,
        "rest_copies_us": copies_us,
        "busy_cores": machine_s / elapsed_s,
        "busy_cores_others": max(0.0, machine_s - ours_s) / elapsed_s,
        "underruns": underruns,
        "inline_renders": inline_renders,
        "jack_xruns": xruns_after - xruns_before,
        "jack_xrun_causes": xrun_causes(log_during, period_us),
        "machine_floor": machine,
        "render_load_p99": highest(samples, "render_load_p99"),
        "render_load_max": highest(samples, "render_load_max"),
        **callback_us(samples),
        "voices_max": highest(samples, "active_voices"),
        "server_requests": counter_delta(before["requests"], after["requests"]),
        "health": {
            "samples": len(latencies),
            "statuses": health["statuses"],
            "p50_ms": ms(percentile(latencies, 0.50)),
            "p99_ms": ms(percentile(latencies, 0.99)),
            "max_ms": ms(max(latencies, default=None)),
        },
        **done,
    }
