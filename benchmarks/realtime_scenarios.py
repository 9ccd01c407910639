"""The scenarios of ``bench_realtime.py``: the load each puts on the service, and how long.

Each builder returns a :data:`realtime_measure.Load` made of the users and programs of
``realtime_load.py``; :func:`scenario_loads` gives every scenario its length and load, by
the letter ``--scenarios`` names it with (their titles: ``realtime_report.TITLES``).
"""

from __future__ import annotations

import argparse
import asyncio
import time
from pathlib import Path
from typing import Any

import realtime_load as load
from realtime_measure import Load, ms, percentile
from realtime_usage import engine_pid, rss_bytes


def idle() -> Load:
    async def run(deadline: float) -> dict[str, Any]:
        await asyncio.sleep(max(0.0, deadline - time.monotonic()))
        return {}

    return run


def hands_and_touches(port: int, args: argparse.Namespace) -> Load:
    async def run(deadline: float) -> dict[str, Any]:
        per_connection = args.touch_rate / args.touch_connections
        touchers = [
            load.paced_touches(port, per_connection, deadline)
            for _ in range(args.touch_connections)
        ]
        hands = [load.hand(port, k, args.move_hz, deadline) for k in range(args.hands)]
        results = await asyncio.gather(*touchers, *hands)
        touches, moved = results[: len(touchers)], results[len(touchers) :]
        statuses: dict[str, int] = {}
        for t in touches:
            for status, n in t["statuses"].items():
                statuses[status] = statuses.get(status, 0) + n
        latencies = [s for t in touches for s in t["latencies_s"]]
        seconds = max(h["seconds"] for h in moved)
        errors = [e for h in moved for e in h["errors"]]
        return {
            "touches": {
                "sent": len(latencies),
                "per_s": len(latencies) / seconds,
                "statuses": statuses,
                "p50_ms": ms(percentile(latencies, 0.50)),
                "p99_ms": ms(percentile(latencies, 0.99)),
            },
            "hands": {
                "count": len(moved),
                "moves": sum(h["moves"] for h in moved),
                "moves_per_s_per_hand": sum(h["moves"] for h in moved) / seconds / len(moved),
                "skipped_frames": sum(h["skipped"] for h in moved),
                "errors": len(errors),
                "first_error": errors[0] if errors else None,
            },
        }

    return run


MEMORY_EVERY_S = 10.0
"""How often the soak samples the resident memory of the service and its engine process."""


def soak(port: int, server_pid: int, args: argparse.Namespace) -> Load:
    async def run(deadline: float) -> dict[str, Any]:
        pids = {"server": server_pid, "engine": engine_pid(server_pid)}

        def memory() -> dict[str, int | None]:
            return {name: None if pid is None else rss_bytes(pid) for name, pid in pids.items()}

        began = time.monotonic()
        series: list[tuple[float, dict[str, int | None]]] = []

        async def sample() -> None:
            while True:
                series.append((time.monotonic() - began, memory()))
                await asyncio.sleep(MEMORY_EVERY_S)

        sampler = asyncio.create_task(sample())
        touches = await load.paced_touches(
            port,
            args.soak_rate,
            deadline,
            lambda k: load.soak_body(k, args.soak_points),
        )
        sampler.cancel()
        series.append((time.monotonic() - began, memory()))
        latencies = touches["latencies_s"]
        return {
            "touches": {
                "sent": len(latencies),
                "statuses": touches["statuses"],
                "p50_ms": ms(percentile(latencies, 0.50)),
                "p99_ms": ms(percentile(latencies, 0.99)),
            },
            "rss_bytes": {"start": series[0][1], "end": series[-1][1], "series": series},
        }

    return run


def bands(port: int, order: str, seed: int, args: argparse.Namespace) -> Load:
    async def run(deadline: float) -> dict[str, Any]:
        touched = await load.band_touches(port, order, seed, args.band_gap_seconds)
        await asyncio.sleep(max(0.0, deadline - time.monotonic()))
        return {"bands": {"order": order, **touched}}

    return run


def with_hogs(inner: Load, hogs: list[Any], count: int) -> Load:
    async def run(deadline: float) -> dict[str, Any]:
        hogs.extend(load.start_hogs(count, deadline - time.monotonic() + 5.0))
        try:
            return {"cpu_hogs": count, **await inner(deadline)}
        finally:
            load.stop(hogs)
            hogs.clear()

    return run


def wrk_flood(wrk: str, port: int, folder: Path, args: argparse.Namespace) -> Load:
    async def run(deadline: float) -> dict[str, Any]:
        seconds = deadline - time.monotonic()
        return {
            "wrk": await load.flood(
                wrk, port, folder, connections=args.flood_connections, seconds=seconds
            )
        }

    return run


def band_seconds(order: str, args: argparse.Namespace) -> float:
    """A band scenario's length: its touches ``--band-gap-seconds`` apart, then the last
    one's 1.5 s and a second more."""
    return len(load.BAND_ORDERS[order]) * args.band_gap_seconds + 2.5


def scenario_loads(
    port: int, server_pid: int, wrk: str, folder: Path, hogs: list[Any], args: argparse.Namespace
) -> dict[str, tuple[float, Load]]:
    """Every scenario's length (s) and load, by its letter.

    Parameters
    ----------
    port : int
        The service's loopback port.
    server_pid : int
        The service's process (the soak samples its memory and its engine process's).
    wrk : str
        The ``wrk`` executable (scenario c).
    folder : Path
        Where scenario c writes its ``wrk`` script.
    hogs : list
        Scenario b's CPU hogs are kept here while they run, so the caller can stop them.
    args : argparse.Namespace
        The command line of ``bench_realtime.py``.
    """
    return {
        "d": (args.quiet_seconds, idle()),
        "a": (args.seconds, hands_and_touches(port, args)),
        "b": (args.seconds, with_hogs(hands_and_touches(port, args), hogs, args.hogs)),
        "c": (args.flood_seconds, wrk_flood(wrk, port, folder, args)),
        "s": (args.seconds, soak(port, server_pid, args)),
        "n": (band_seconds("new", args), bands(port, "new", 1_001, args)),
        "o": (band_seconds("disagreeing", args), bands(port, "disagreeing", 1_002, args)),
    }
