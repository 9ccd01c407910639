"""What ``bench_realtime.py`` prints: the machine, JACK's own floor, then a Markdown table
with one row per scenario (``—`` where a figure is missing: a service that does not report
it), and the soak's resident memory."""

from __future__ import annotations

import statistics
from typing import Any

TITLES = {
    "d": "quiet (no load)",
    "a": "4 hands at 90 Hz + 50 touches/s",
    "b": "same + CPU hog on every core",
    "c": "wrk flood of POST /touch",
    "s": "soak: distinct long noise touches",
    "n": "noise bands the engine does not hold yet",
    "o": "noise bands in the disagreeing order",
}


def mb(size: int | None) -> str:
    return "—" if size is None else f"{size / 1e6:.0f}"


def percent(fraction: float | None) -> str:
    return "—" if fraction is None else f"{fraction:.0%}"


def number(value: float | None, digits: int = 1) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def statuses_text(statuses: dict[str, int]) -> str:
    return ", ".join(f"{n} × {s}" for s, n in sorted(statuses.items())) or "—"


def touch_statuses(result: dict[str, Any]) -> str:
    """The client's count of /touch answers, else the server's (for the wrk flood)."""
    if "touches" in result:
        return statuses_text(result["touches"]["statuses"])
    by_status = {
        key.rsplit(" ", 1)[1]: n
        for key, n in result["server_requests"].items()
        if key.startswith("POST /touch ")
    }
    return statuses_text(by_status)


def load_text(result: dict[str, Any]) -> str:
    parts = []
    if "hands" in result:
        h, t = result["hands"], result["touches"]
        parts.append(f"{h['moves_per_s_per_hand']:.0f} moves/s/hand, {t['per_s']:.0f} touches/s")
        if h["errors"]:
            parts.append(f"{h['errors']} WS errors")
    if "bands" in result:
        b = result["bands"]
        parts.append(
            f"{b['touches']} noise touches, {b['order']} order: {statuses_text(b['statuses'])}"
        )
    if "cpu_hogs" in result:
        parts.append(f"{result['cpu_hogs']} hogs")
    if "wrk" in result:
        w = result["wrk"]
        parts.append(
            f"wrk {number(w['requests_per_s'], 0)} req/s, {w['non_2xx_3xx']} non-2xx/3xx"
            + (f", socket errors {w['socket_errors']}" if w["socket_errors"] else "")
        )
    return "; ".join(parts) or "—"


def xruns_text(result: dict[str, Any]) -> str:
    """``total (late wake-ups / slow cycles or late clients)``: ``realtime_floor.xrun_causes``."""
    causes = result.get("jack_xrun_causes", {})
    slow = sum(n for key, n in causes.items() if key != "late_wakeup")
    return f"{result['jack_xruns']} ({causes.get('late_wakeup', 0)} / {slow})"


def floor_text(result: dict[str, Any]) -> str:
    """``late of all (max ms)``: a do-nothing real-time thread's late wake-ups
    (``realtime_floor.LatencyProbe``)."""
    floor = result.get("machine_floor")
    if floor is None:
        return "—"
    return (
        f"{floor['late_wakeups']} of {floor['wakeups']} ({floor['max_latency_us'] / 1000:.1f} ms)"
    )


def stalls_text(result: dict[str, Any]) -> str:
    """``in of all (by chance); N beyond``: JACK's xruns during a stall the probe saw, and
    those beyond the machine (``realtime_floor.in_stalls``)."""
    seen = result.get("machine_floor", {}).get("xruns_in_stalls")
    if seen is None:
        return "—"
    return (
        f"{seen['in_stalls']} of {seen['xruns']} ({seen['by_chance']:.2f}); "
        f"{seen['beyond_machine']} beyond"
    )


def callback_text(result: dict[str, Any], yardstick_us: float) -> str:
    """``p50 / p99 µs (p50 / p99 yardsticks)`` of the callback's own time; a service that
    does not report it: its p99 from its render load, marked ``≈``."""
    p50, p99 = result.get("callback_p50_us"), result.get("callback_p99_us")
    if p99 is None and result.get("callback_p99_us_from_load") is not None:
        p99 = result["callback_p99_us_from_load"]
        return f"— / ≈{p99:.0f} µs (— / ≈{p99 / yardstick_us:.0f})"
    if p99 is None:
        return "—"
    ratio = "—" if p50 is None else f"{p50 / yardstick_us:.0f}"
    return f"{number(p50, 0)} / {p99:.0f} µs ({ratio} / {p99 / yardstick_us:.0f})"


def rest_yardstick_us(result: dict[str, Any], default_us: float) -> float:
    """The median of the copies timed in a scenario's rest (``default_us``, the run's
    yardstick, for a scenario without them)."""
    copies = result.get("rest_copies_us") or [default_us]
    return statistics.median(copies)


def rest_copies_text(result: dict[str, Any]) -> str:
    """``median (min-max)`` of the copies timed in a scenario's rest, µs."""
    copies = result.get("rest_copies_us")
    if not copies:
        return "—"
    return f"{statistics.median(copies):.2f} ({min(copies):.2f}-{max(copies):.2f})"


def flood_text(result: dict[str, Any]) -> str:
    """``POST /touch accepted/s vs GET /health req/s (ratio)`` of scenario c."""
    touch, health = result.get("wrk"), result.get("health_wrk")
    if touch is None or health is None:
        return "—"
    accepted, per_s = touch.get("accepted_per_s"), health.get("requests_per_s")
    if accepted is None or not per_s:
        return "—"
    return f"{accepted:.0f} vs {per_s:.0f} ({accepted / per_s:.2f})"


def pair_table(results: dict[str, Any]) -> str:
    """This checkout beside the other one (``--pair``), scenario by scenario."""
    yardstick_us = results["block_copy_us"]
    installs = [("this", results)]
    if "pair" in results:
        installs.append(("pair", results["pair"]))
    lines = [
        "| scenario | install | underruns | JACK xruns | callback p50 / p99 (yardsticks) "
        "| yardstick in the rest, µs (range) "
        "| render load p99 | /touch accepted/s vs /health req/s | RT probe late (max) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for key in results["scenarios"]:
        for name, figures in installs:
            r = figures["scenarios"][key]
            lines.append(
                f"| ({key}) {TITLES[key]} | {name} | {number(r['underruns'], 0)} "
                f"| {xruns_text(r)} | {callback_text(r, rest_yardstick_us(r, yardstick_us))} "
                f"| {rest_copies_text(r)} "
                f"| {percent(r['render_load_p99'])} | {flood_text(r)} | {floor_text(r)} |"
            )
    return "\n".join(lines)


def table(results: dict[str, Any]) -> str:
    lines = [
        "| scenario | s | underruns (inline renders) | JACK xruns (timer / slow) "
        "| render load p99 | max | voices max | /touch answered | /health p50 / p99 ms | load "
        "| busy cores (others) "
        "| RT probe late (max) | xruns in the probe's stalls (by chance); beyond the machine |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key, r in results["scenarios"].items():
        health = r["health"]
        lines.append(
            f"| ({key}) {TITLES[key]} | {r['seconds']:.0f} | {number(r['underruns'], 0)} "
            f"({number(r.get('inline_renders'), 0)}) "
            f"| {xruns_text(r)} | {percent(r['render_load_p99'])} "
            f"| {percent(r['render_load_max'])} | {number(r['voices_max'], 0)} "
            f"| {touch_statuses(r)} | {number(health['p50_ms'])} / {number(health['p99_ms'])} "
            f"| {load_text(r)} | {r['busy_cores']:.1f} ({r['busy_cores_others']:.1f}) "
            f"| {floor_text(r)} | {stalls_text(r)} |"
        )
    return "\n".join(lines)


def print_report(results: dict[str, Any], channels: int, memory_every_s: float) -> None:
    """Print the results of a run: ``channels`` is the width of the yardstick's block,
    ``memory_every_s`` how often the soak sampled resident memory."""
    period_frames, sample_rate_hz = results["period_frames"], results["sample_rate_hz"]
    print(
        f"machine: {results['cpus']} cpus, load average {results['load_avg_1min']:.2f} -> "
        f"{results['load_avg_1min_after']:.2f}; JACK dummy {sample_rate_hz} Hz, "
        f"{period_frames}-frame periods ({period_frames / sample_rate_hz * 1e3:.2f} ms)"
    )
    print(
        f"yardstick: numpy copy of one 128 x {channels} block "
        f"{results['block_copy_us']:.2f} µs; render load window "
        f"{number(results['render_load_window_s'])} s, "
        f"rest {results['config']['rest_seconds']:g} s; device profile block "
        f"{results['profile_block_frames']} frames\n"
    )
    base = results["floor"]
    print(
        f"floor: JACK alone for {base['seconds']:g} s: {xruns_text(base)} xruns "
        "(timer: the dummy driver woke late; slow: a cycle, that is a client, took too long); "
        f"a do-nothing SCHED_FIFO thread: {floor_text(base)} wake-ups a period or more late\n"
    )
    print(table(results))
    if "pair" in results:
        print(f"\npaired with {results['pair']['checkout']}: {results['pair']['device']}")
    print(f"\nthis checkout: {results['device']}\n")
    print(pair_table(results))
    for key, result in results["scenarios"].items():
        if "rss_bytes" in result:
            series = result["rss_bytes"]["series"]
            print(f"\n({key}) resident memory, MB, every {memory_every_s:g} s:")
            for name in series[0][1]:
                print(f"  {name}: " + " ".join(f"{mb(rss[name])}" for _, rss in series))
    print(
        "\ntarget (docs/engine.md, Where to measure): at 128 frames at most 2 underruns "
        "in each of a, c and n (a: at most 4 at 64 frames); under a at 128 frames the "
        "callback's p50 <= 200 and "
        "p99 <= 1,100 yardsticks; the flood's excess refused (503) or stolen, and POST /touch "
        "accepted per second at least 0.8 of GET /health's"
    )
