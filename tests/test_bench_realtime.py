"""``benchmarks/bench_realtime.py`` runs end to end: JACK, the service, its loads, its report.

A smoke run (2 s of hands and touches, a 1 s ``wrk`` flood): it checks that every figure
was measured and that the loads reached the service, never how fast anything was.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.jack import unavailable

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_realtime_benchmark_measures_every_figure(tmp_path: Path) -> None:
    if shutil.which("jackd") is None:
        unavailable("jackd not found (Debian package jackd2)")
    if shutil.which("cyclictest") is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("cyclictest is required under CI (Debian package rt-tests)")
        pytest.skip("cyclictest not found (Debian package rt-tests)")
    if shutil.which("wrk") is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("the load tool is required under CI: wrk not found (Debian package wrk)")
        pytest.skip("wrk not found (Debian package wrk)")
    report = tmp_path / "realtime.json"
    command = [sys.executable, str(ROOT / "benchmarks" / "bench_realtime.py"), "--quick"]
    command += ["--seconds", "2", "--flood-seconds", "1", "--scenarios", "a,c"]
    command += ["--json", str(report)]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    result = subprocess.run(command, capture_output=True, text=True, timeout=240, env=env)
    assert result.returncode == 0, result.stderr[-3000:]

    results = json.loads(report.read_text(encoding="utf-8"))
    assert results["device"] == {
        "backend": "sounddevice",
        "output_device": "system",
        "block_frames": 128,
        "sample_rate_hz": 48000,
        "period_frames": 128,
    }
    assert results["block_copy_us"] > 0.0  # the yardstick, a 128 x 8 copy
    for key in ("a", "c"):
        scenario = results["scenarios"][key]
        assert scenario["underruns"] >= 0 and scenario["inline_renders"] >= 0
        assert scenario["jack_xruns"] >= 0
        # the yardstick timed in the scenario's rest (1 s with --quick): at least once
        assert scenario["rest_copies_us"] and min(scenario["rest_copies_us"]) > 0.0
        assert 0.0 < scenario["render_load_p99"] <= scenario["render_load_max"]
        # the callback's own time, read from /metrics while the scenario ran
        assert 0.0 < scenario["callback_p50_us"] <= scenario["callback_p99_us"]
        assert scenario["callback_p99_us"] <= scenario["callback_max_us"]
        assert scenario["health"]["samples"] > 0
        assert scenario["health"]["p50_ms"] <= scenario["health"]["p99_ms"]
        floor = scenario["machine_floor"]  # cyclictest ran beside the scenario
        assert 0 <= floor["late_wakeups"] <= floor["wakeups"]
        assert floor["wakeups"] > 0 and floor["max_latency_us"] >= 0
        # a wake-up a period late is a stall too, and each stall was due during the run
        assert len(floor["stalls"]) >= floor["late_wakeups"]
        seen = floor["xruns_in_stalls"]
        assert seen["xruns"] == scenario["jack_xruns"]
        assert 0 <= seen["in_stalls"] <= seen["xruns"] and 0.0 <= seen["stall_share"] <= 1.0
        assert 0 <= seen["beyond_machine"] <= seen["xruns"] - seen["in_stalls"]
        assert set(scenario["jack_xrun_causes"]) >= {"late_wakeup", "slow_cycle"}
    hands = results["scenarios"]["a"]
    assert hands["hands"]["count"] == 4 and hands["hands"]["moves"] > 0
    touches = hands["touches"]["statuses"]
    assert sum(touches.values()) == hands["touches"]["sent"] > 0
    assert hands["server_requests"].get("POST /touch 202", 0) >= touches.get("202", 0) > 0
    flood = results["scenarios"]["c"]["wrk"]
    assert flood["requests_per_s"] > 0
    assert sum(flood["statuses"].values()) == flood["requests"]
    answered = sum(n for s, n in flood["statuses"].items() if not s.startswith(("2", "3")))
    assert answered == flood["non_2xx_3xx"]
    accepted = sum(n for s, n in flood["statuses"].items() if s.startswith("2"))
    assert flood["accepted_per_s"] == pytest.approx(
        flood["requests_per_s"] * accepted / flood["requests"]
    )
    health = results["scenarios"]["c"]["health_wrk"]  # GET /health flooded the same way
    assert health["requests_per_s"] > 0 and set(health["statuses"]) == {"200"}
    assert "| (a) " in result.stdout and "| (c) " in result.stdout
    assert "| (c) wrk flood of POST /touch | this |" in result.stdout  # the side-by-side table


def test_an_xrun_is_the_machines_only_within_a_stall_the_probe_saw() -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from realtime_floor import STALL_WINDOW_S, in_stalls, xrun_kinds
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    before_s, after_s = STALL_WINDOW_S
    stalls = [[10.0, 3000.0], [20.0, 2000.0]]  # due at 10 s, 3 ms late; at 20 s, 2 ms late
    xruns = [
        10.003 + before_s - 1e-4,  # reported just within the window after the first stall
        10.003 + before_s + 1e-4,  # just after it
        20.0 - after_s + 1e-4,  # just before the second stall began
        30.0,  # far from both
    ]
    seen = in_stalls(xruns, stalls, seconds=100.0)
    assert seen["xruns"] == 4 and seen["in_stalls"] == 2 and seen["beyond_machine"] == 2
    # JACK's own timer woke late for the last: no client was slow, so it is the machine's
    kinds = ["slow_cycle", "slow_cycle", "slow_cycle", "late_wakeup"]
    assert in_stalls(xruns, stalls, seconds=100.0, kinds=kinds)["beyond_machine"] == 1
    log = "JackTimedDriver::Process XRun = 2000 usec\nJackTimedDriver::Process XRun = 100 usec\n"
    assert xrun_kinds(log, period_us=2667) == ["slow_cycle", "late_wakeup"]
    # causes that cannot be matched one to one are not used
    assert in_stalls(xruns, stalls, seconds=100.0, kinds=kinds[:3])["beyond_machine"] == 2
    covered_s = (0.003 + before_s + after_s) + (0.002 + before_s + after_s)
    assert seen["stall_share"] == pytest.approx(covered_s / 100.0)
    assert seen["by_chance"] == pytest.approx(4 * covered_s / 100.0)
    # overlapping stalls cover their union once
    merged = in_stalls([], [[10.0, 3000.0], [10.001, 3000.0]], seconds=1.0)
    assert merged["stall_share"] == pytest.approx(0.004 + before_s + after_s)


def test_the_callbacks_time_is_read_from_metrics_and_set_beside_the_pairs() -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from realtime_http import parse_metrics
        from realtime_measure import callback_us
        from realtime_report import callback_text, flood_text
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    text = (
        'phantomtouch_callback_seconds{quantile="0.5"} 0.0002\n'
        'phantomtouch_callback_seconds{quantile="0.99"} 0.0011\n'
        'phantomtouch_callback_seconds{quantile="1"} 0.003\n'
    )
    first = parse_metrics(text)
    assert (first["callback_p50_s"], first["callback_p99_s"], first["callback_max_s"]) == (
        0.0002,
        0.0011,
        0.003,
    )
    later = {**first, "callback_p50_s": 0.0004, "callback_p99_s": 0.0009}
    older = parse_metrics('phantomtouch_render_load{quantile="0.99"} 0.5\n')
    assert older["callback_p99_s"] is None  # a service without the metric
    figures = callback_us([first, later, older])
    # the median of the sampled medians; the highest p99 and largest
    assert figures["callback_p50_us"] == pytest.approx(300.0)
    assert figures["callback_p99_us"] == pytest.approx(1100.0)
    assert figures["callback_max_us"] == pytest.approx(3000.0)
    assert callback_text(figures, yardstick_us=0.5) == "300 / 1100 µs (600 / 2200)"
    # a service without it: its p99 from its render load, marked as such
    derived = {"callback_p50_us": None, "callback_p99_us": None, "callback_p99_us_from_load": 500.0}
    assert callback_text(derived, yardstick_us=0.5) == "— / ≈500 µs (— / ≈1000)"
    flood = {"wrk": {"accepted_per_s": 800.0}, "health_wrk": {"requests_per_s": 1000.0}}
    assert flood_text(flood) == "800 vs 1000 (0.80)"
    assert flood_text({"wrk": {"accepted_per_s": 800.0}}) == "—"
