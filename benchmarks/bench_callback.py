"""The audio callback alone, in this process: p50 and p99 of one call, in µs and yardsticks.

The real :class:`~phantomtouch.engine.local_audio.Engine` (front, admission, scheduler, voices,
mixer, render-ahead thread) plays into a sink pulled by hand, so nothing but the
callback's own work is timed: ``Scheduler.render`` on one block, wall time
(``perf_counter``). Scenes, each at 128 and at 64 frames a block:

- ``idle``: nothing sounds;
- ``vr``: a VR scene's load: 4 contacts down, each moved every other block (two of them
  in one block, the other two in the next: 94 Hz hands at 128 frames), and a ``vr/tap``
  (0.15 s) started every 20 ms, so about 8 sound at once.

The moves and taps go through the engine's own front between blocks, as a WebSocket or a
``POST /touch`` would; that host work is not timed.

Each scene runs ``hot``, one callback right after the other, and ``paced``, each callback
a period after the last one began, the thread asleep in between, as a sound card calls
it; the ``vr`` scene also ``busy``, paced so but the thread busy in between. On a machine
whose idle cores halt (a virtual machine, a laptop saving power) a paced callback can cost
several times a hot one, as the core wakes cold: the paced figures are the ones the
service's ``phantomtouch_callback_seconds`` shows there, and ``busy`` shows how much of
that the idle core itself costs.

The yardstick is one numpy copy of a 128 x 8 float32 block (``yardstick.py``: the median
of 2,000 timings of 100 copies), in the same process: targets are stated in yardsticks so
they carry from machine to machine (issue 40: the ``vr`` scene at 128 frames, p50 <= 200
and p99 <= 1,100).

Run: ``python benchmarks/bench_callback.py [--blocks 4000] [--json]`` (about 50 s with
the defaults, most of it the paced scenes). ``--against PYTHON`` runs this file with
another install's interpreter (one that imports another checkout's ``phantomtouch``) and
this one in turn, ``--rounds`` times each, and prints every scene's medians side by side.
Nothing here is asserted.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np
from yardstick import block_copy_s

import phantomtouch as pt
from phantomtouch.engine import Engine
from phantomtouch.output.sinks import CaptureSink

CONTACTS = 4
TAP_EVERY_S = 0.02
"""50 ``vr/tap`` a second, as in the issue's VR load."""
WARM_BLOCKS = 200
SCENES = (("idle", "hot"), ("vr", "hot"), ("idle", "paced"), ("vr", "paced"), ("vr", "busy"))
"""Each scene and how its callbacks come: ``hot``, ``paced`` (asleep between periods) or
``busy`` (paced, looping between periods)."""


def scene_s(
    scene: str, block_frames: int, blocks: int, paced: bool = False, busy: bool = False
) -> np.ndarray:
    """Wall and thread CPU seconds of each of ``blocks`` callbacks after ``WARM_BLOCKS``,
    shape (blocks, 2); ``paced``: each a period after the last one began, the thread
    asleep in between (``busy``: looping)."""
    device = pt.DeviceProfile.default().model_copy(update={"block_frames": block_frames})
    sink = CaptureSink(device)
    engine = Engine(device, sink)
    engine.start()
    render = engine.core.scheduler.render
    out = np.zeros((block_frames, device.channels), dtype=np.float32)
    tap = pt.plan(pt.preset("vr/tap"), device)
    tap_every = max(1, round(TAP_EVERY_S * device.sample_rate_hz / block_frames))
    times = np.empty((blocks, 2))
    period_s = block_frames / device.sample_rate_hz
    due_s = time.perf_counter()
    if scene == "vr":
        for k in range(CONTACTS):
            engine.contact_down("bench", f"c{k}", 0.9 * k, 2.0 + 3.0 * k, intensity=0.4)
    for block in range(WARM_BLOCKS + blocks):
        if scene == "vr":
            phase = block / 150.0
            for k in range(block % 2, CONTACTS, 2):
                x_cm = 1.9 + 1.7 * np.cos(phase + k)
                engine.contact_move("bench", f"c{k}", x_cm, 7.2 + 6.5 * np.sin(phase + k))
            if block % tap_every == 0:
                engine.schedule(tap, owner="taps")
        if paced:
            due_s += period_s
            if busy:
                while time.perf_counter() < due_s:
                    pass
            else:
                time.sleep(max(0.0, due_s - time.perf_counter()))
        began, began_cpu = time.perf_counter(), time.thread_time()
        render(out)
        spent = time.perf_counter() - began, time.thread_time() - began_cpu
        if block >= WARM_BLOCKS:
            times[block - WARM_BLOCKS] = spent
    engine.close()
    return times


def measure(blocks: int) -> dict[str, Any]:
    stick = block_copy_s()
    rows: dict[str, Any] = {"yardstick_us": stick * 1e6}
    for block_frames in (128, 64):
        for scene, wait in SCENES:
            times = scene_s(scene, block_frames, blocks, wait != "hot", wait == "busy")
            p50, p99 = np.percentile(times[:, 0], [50, 99])
            cpu_p50, cpu_p99 = np.percentile(times[:, 1], [50, 99])
            rows[f"{scene}@{block_frames}{'' if wait == 'hot' else ' ' + wait}"] = {
                "p50_us": p50 * 1e6,
                "p99_us": p99 * 1e6,
                "p50_yardsticks": p50 / stick,
                "p99_yardsticks": p99 / stick,
                "cpu_p50_us": cpu_p50 * 1e6,
                "cpu_p99_us": cpu_p99 * 1e6,
                "period_share_p99": p99 / (block_frames / 48000),
            }
    return rows


def paired(other_python: str, rounds: int, blocks: int) -> dict[str, list[dict[str, Any]]]:
    """Runs of this file under ``other_python`` ("other") and this interpreter ("this"),
    alternating."""
    runs: dict[str, list[dict[str, Any]]] = {"other": [], "this": []}
    command = [__file__, "--json", "--blocks", str(blocks)]
    for _ in range(rounds):
        for name, python in (("other", other_python), ("this", sys.executable)):
            done = subprocess.run([python, *command], capture_output=True, text=True, check=True)
            runs[name].append(json.loads(done.stdout))
    return runs


def print_rows(label: str, rows: dict[str, Any]) -> None:
    print(f"{label}: yardstick {rows['yardstick_us']:.3f} µs")
    print(
        f"  {'scene':16} {'p50 µs':>8} {'p99 µs':>8} {'p50 yd':>7} {'p99 yd':>7} "
        f"{'cpu p50':>8} {'cpu p99':>8} {'p99/period':>10}"
    )
    for scene, row in rows.items():
        if scene == "yardstick_us":
            continue
        print(
            f"  {scene:16} {row['p50_us']:8.1f} {row['p99_us']:8.1f} {row['p50_yardsticks']:7.0f} "
            f"{row['p99_yardsticks']:7.0f} {row['cpu_p50_us']:8.1f} {row['cpu_p99_us']:8.1f} "
            f"{row['period_share_p99']:10.1%}"
        )


def median_rows(runs: list[dict[str, Any]]) -> dict[str, Any]:
    rows: dict[str, Any] = {"yardstick_us": statistics.median(r["yardstick_us"] for r in runs)}
    for scene in runs[0]:
        if scene != "yardstick_us":
            rows[scene] = {
                key: statistics.median(r[scene][key] for r in runs) for key in runs[0][scene]
            }
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, default=4000)
    parser.add_argument("--against", metavar="PYTHON", help="another install's interpreter")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.against:
        runs = paired(args.against, args.rounds, args.blocks)
        if args.json:
            print(json.dumps(runs, indent=2))
            return
        for name, label in (("other", args.against), ("this", sys.executable)):
            print_rows(f"{label} (median of {args.rounds})", median_rows(runs[name]))
        return
    rows = measure(args.blocks)
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print_rows(sys.executable, rows)


if __name__ == "__main__":
    main()
