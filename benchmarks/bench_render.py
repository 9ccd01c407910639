"""Render speed against two yardsticks measured in the same run.

- real time: seconds of audio rendered per second of CPU, on one core;
- a plain per-sample Python loop of the same algorithm (position -> barycentric gains
  with the power law -> carrier x envelope x gain), timed on a short stretch;
- a numpy copy of an output array of the same size (a memcpy);
- for ``exp2/central`` (a 100 Hz sine held between two actuators), the compute floor: one
  carrier sine a frame (the renderer's own sine source) times eight gains, the faster of a
  broadcast product and ``np.outer``, into an output array. ``x floor`` is the render's
  time over it (issue 40: at most 1.3).

Run: ``python benchmarks/bench_render.py [--json]``. Targets (issue): >= 1000x real time
for one 8-channel 48 kHz pattern, and within 10x of the copy.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable

import numpy as np

import phantomtouch as pt
from phantomtouch.renderer.carriers import SineSource
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.trajectory import envelope_at, positions_at

PATTERNS = (
    "exp2/central",
    "exp2/curved",
    "exp1/sine100-low-v3",
    "exp1/sine100-high-v10-am",
    "exp1/noise-low-v18",
)
FLOOR_PATTERN = "exp2/central"


def best_of(fn: Callable[[], object], repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        start = time.process_time()
        fn()
        best = min(best, time.process_time() - start)
    return best


def per_sample_loop(plan: pt.Plan, frames: int) -> np.ndarray:
    """The algorithm one sample at a time in plain Python (the naive reference)."""
    geometry = Geometry.for_device(plan.device)
    sample_rate = plan.sample_rate_hz
    freq_hz = getattr(plan.pattern.carrier, "freq_hz", 100.0)
    out = np.zeros((frames, plan.channels), dtype=np.float32)
    positions = geometry.positions_cm
    triangles = geometry.triangles
    rows = geometry.row_y_cm
    for n in range(frames):
        t = n / sample_rate
        points, _ = positions_at(plan, np.array([t]))
        px, py = float(points[0, 0]), float(points[0, 1])
        env = float(envelope_at(plan, np.array([t]))[0]) * plan.amplitude
        carrier = math.sin(2.0 * math.pi * ((n * freq_hz / sample_rate) % 1.0))
        if plan.pattern.mode == "1d":
            py = min(max(py, rows[0]), rows[-1])
            r = min(int(np.searchsorted(rows, py, side="right")) - 1, len(rows) - 2)
            beta = (py - rows[r]) / (rows[r + 1] - rows[r])
            for row, weight in ((r, 1.0 - beta), (r + 1, beta)):
                for member in geometry.row_members[row]:
                    out[n, geometry.columns[member]] = carrier * env * math.sqrt(weight)
            continue
        best, best_w = 0, (-math.inf, 0.0, 0.0)
        for k, (a, b, c) in enumerate(triangles):
            (ax, ay), (bx, by), (cx, cy) = positions[a], positions[b], positions[c]
            det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
            w1 = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) / det
            w2 = ((bx - ax) * (py - ay) - (px - ax) * (by - ay)) / det
            w = (1.0 - w1 - w2, w1, w2)
            if min(w) > min(best_w):
                best, best_w = k, w
        for vertex, weight in zip(triangles[best], best_w, strict=True):
            out[n, geometry.columns[vertex]] = carrier * env * math.sqrt(max(weight, 0.0))
    return out


def floor_s(plan: pt.Plan, repeats: int) -> float:
    """The compute floor of a sine pattern: one carrier sine a frame times eight gains."""
    source = SineSource(getattr(plan.pattern.carrier, "freq_hz", 100.0), plan.sample_rate_hz)
    gains = np.linspace(0.1, 0.8, plan.channels, dtype=np.float32)
    out = np.empty((plan.frames, plan.channels), dtype=np.float32)

    def broadcast() -> None:
        np.multiply(source.block(0, plan.frames)[:, None], gains, out=out)

    def outer() -> None:
        np.outer(source.block(0, plan.frames), gains, out=out)

    return min(best_of(broadcast, repeats), best_of(outer, repeats))


def measure(name: str, repeats: int) -> dict[str, float]:
    pattern = pt.preset(name)
    plan = pt.plan(pattern)
    output = pt.render(pattern)
    render_s = best_of(lambda: pt.render(pattern), repeats)
    copy_s = best_of(lambda: output.copy(), repeats * 3)
    loop_frames = 4800
    loop_s = best_of(lambda: per_sample_loop(plan, loop_frames), 1) * plan.frames / loop_frames
    result = {
        "duration_s": plan.duration_s,
        "render_ms": render_s * 1e3,
        "realtime_x": plan.duration_s / render_s,
        "vs_copy_x": render_s / copy_s,
        "vs_python_loop_speedup_x": loop_s / render_s,
    }
    if name == FLOOR_PATTERN:
        result["vs_floor_x"] = render_s / floor_s(plan, repeats)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = {name: measure(name, args.repeats) for name in PATTERNS}
    if args.json:
        print(json.dumps(results, indent=2))
        return
    header = f"{'pattern':28} {'dur s':>6} {'ms':>7} {'x real time':>12} {'x copy':>7}"
    print(f"{header} {'x faster than loop':>19} {'x floor':>8}")
    for name, r in results.items():
        floor = f"{r['vs_floor_x']:8.2f}" if "vs_floor_x" in r else ""
        print(
            f"{name:28} {r['duration_s']:6.2f} {r['render_ms']:7.2f} {r['realtime_x']:12.0f} "
            f"{r['vs_copy_x']:7.1f} {r['vs_python_loop_speedup_x']:19.0f} {floor}"
        )


if __name__ == "__main__":
    main()
