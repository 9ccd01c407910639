"""Engine speed and robustness, each against a yardstick measured in the same run.

1. Render time of one block (256 frames, or ``--block-frames``) with 16 active voices
   (what the audio callback does per block: drain the queue, render the voices, limit,
   calibrate), as a fraction of the block period (5.33 ms at 256 frames). Targets: p99
   <= 10 % with 16 voices, <= 25 % with 64. Scenes: 16 pattern
   voices (the paper's 12 s stimuli: sine, combined, noise, with and without AM), the
   same rendered block by block (render-ahead off), 16 moving contacts, 8 + 8, and as
   many pattern voices as the default voice cap lets sound at once.
   Wall time (``perf_counter``) includes whatever else the machine runs; CPU time
   (``thread_time``) is the engine's own cost. Yardstick: a numpy copy of one block,
   timed the same way.
2. Underruns during 60 s at 128-frame blocks (2.67 ms) on JACK's dummy driver
   (``jackd -p 128``, a private server) while another thread keeps the GIL busy with
   JSON work; 8 pattern voices and 8 contacts moving at 90 Hz play. Counted from
   PortAudio's underflow flags and JACK's xrun reports. Target: 0. The 60 s run has the
   engine in a process of its own (``ProcessEngine``, as the service runs it; the JSON
   thread stays in this process). Two shorter runs show why: the engine in this
   process, with and without the JSON thread; there the callback's start-to-start gaps
   and durations show where deadlines were missed. Every run reports the engine's own
   render load (p99 and largest callback time over its last 4096 blocks, as a fraction
   of the block period).

Run: ``python benchmarks/bench_engine.py [--seconds 60] [--diagnose-seconds 20]
[--blocks 3000] [--block-frames 256] [--json]`` (about 2 minutes with the defaults). Nothing here is
asserted; numbers depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.support.jack

import phantomtouch as pt
from phantomtouch.engine import Engine
from phantomtouch.engine.front import MAX_VOICES
from phantomtouch.engine.local_audio import RENDER_AHEAD_FRAMES
from phantomtouch.output.sinks import RenderFn, Sink

PATTERN_PRESETS = [n for n in pt.preset_names() if n.startswith("exp1/") and "-v3" in n][::2]


class TimedSink:
    """A sink the benchmark pulls by hand, timing each block (wall and CPU time)."""

    backend = "capture"
    realtime = False
    output_device = None
    underruns = 0
    output_latency_s = 0.0
    period_source = "profile"

    def __init__(self, device: pt.DeviceProfile) -> None:
        self.sample_rate_hz = device.sample_rate_hz
        self.block_frames = self.period_frames = device.block_frames
        self.channels = device.channels
        self._render: RenderFn | None = None
        self._buffer = np.zeros((device.block_frames, device.channels), dtype=np.float32)

    def start(self, render: RenderFn) -> None:
        self._render = render

    def close(self) -> None:
        self._render = None

    def tick(self) -> tuple[float, float]:
        assert self._render is not None
        wall, cpu = time.perf_counter(), time.thread_time()
        self._render(self._buffer)
        return time.perf_counter() - wall, time.thread_time() - cpu


def scene_times(
    patterns: int, contacts: int, blocks: int, render_ahead: int, block_frames: int
) -> np.ndarray:
    """Wall and CPU seconds per block, shape (blocks, 2), after 100 warm-up blocks."""
    device = pt.DeviceProfile.default().model_copy(update={"block_frames": block_frames})
    sink = TimedSink(device)
    engine = Engine(device, sink, render_ahead_frames=render_ahead)
    engine.start()
    for k in range(patterns):
        engine.schedule(pt.preset(PATTERN_PRESETS[k % len(PATTERN_PRESETS)]), start_frame=37 * k)
    for k in range(contacts):
        engine.contact_down("bench", f"c{k}", 0.2 * k % 3.8, 1.0 + 0.8 * k, intensity=0.3)
    times = np.empty((blocks, 2))
    for block in range(blocks + 100):
        if contacts and block % 2 == 0:  # 94 Hz: every contact moves
            phase = block / 200.0
            for k in range(contacts):
                y_cm = 7.2 + 6.0 * np.sin(phase + k)
                engine.contact_move("bench", f"c{k}", 1.9 + 1.5 * np.cos(phase + k), y_cm)
        elapsed = sink.tick()
        if block >= 100:
            times[block - 100] = elapsed
    engine.close()
    return times


def copy_times(blocks: int, block_frames: int) -> np.ndarray:
    block = np.zeros((block_frames, 8), dtype=np.float32)
    times = np.empty((blocks, 2))
    for i in range(blocks):
        wall, cpu = time.perf_counter(), time.thread_time()
        block.copy()
        times[i] = time.perf_counter() - wall, time.thread_time() - cpu
    return times


def render_benchmark(blocks: int, block_frames: int) -> list[dict[str, Any]]:
    period_s = block_frames / 48000
    scenes = [
        ("16 patterns", 16, 0, RENDER_AHEAD_FRAMES),
        ("16 patterns, render-ahead off", 16, 0, 0),
        ("16 moving contacts", 0, 16, RENDER_AHEAD_FRAMES),
        ("8 patterns + 8 contacts", 8, 8, RENDER_AHEAD_FRAMES),
        (f"{MAX_VOICES} patterns (the voice cap)", MAX_VOICES, 0, RENDER_AHEAD_FRAMES),
    ]
    measured = [(name, scene_times(p, c, blocks, a, block_frames)) for name, p, c, a in scenes]
    measured.append(("yardstick: numpy copy of a block", copy_times(blocks, block_frames)))
    copy_p50 = float(np.percentile(measured[-1][1][:, 0], 50))
    rows = []
    for name, times in measured:
        wall, cpu = times[:, 0], times[:, 1]
        rows.append(
            {
                "scene": name,
                "wall_p50_us": float(np.percentile(wall, 50) * 1e6),
                "wall_p99_us": float(np.percentile(wall, 99) * 1e6),
                "wall_max_us": float(wall.max() * 1e6),
                "wall_p99_of_period": float(np.percentile(wall, 99) / period_s),
                "cpu_p50_us": float(np.percentile(cpu, 50) * 1e6),
                "cpu_p99_us": float(np.percentile(cpu, 99) * 1e6),
                "cpu_p99_of_period": float(np.percentile(cpu, 99) / period_s),
                "wall_p50_in_copies": float(np.percentile(wall, 50)) / copy_p50,
            }
        )
    return rows


class CallbackProbe:
    """Wraps the engine's render function: start times and durations of each callback."""

    def __init__(self, render: RenderFn, capacity: int) -> None:
        self._render = render
        self.starts = np.zeros(capacity)
        self.durations = np.zeros(capacity)
        self.count = 0

    def __call__(self, out: np.ndarray) -> None:
        began = time.perf_counter()
        self._render(out)
        i = self.count
        if i < len(self.starts):
            self.starts[i] = began
            self.durations[i] = time.perf_counter() - began
        self.count = i + 1


class ProbedSink:
    """A sink wrapped so that every callback is timed by a :class:`CallbackProbe`."""

    def __init__(self, inner: Sink, capacity: int) -> None:
        self._inner = inner
        self._capacity = capacity
        self.probe = CallbackProbe(lambda out: None, 0)
        self.backend = inner.backend
        self.realtime = inner.realtime
        self.sample_rate_hz = inner.sample_rate_hz
        self.block_frames = inner.block_frames
        self.period_frames = inner.period_frames
        self.period_source = inner.period_source
        self.channels = inner.channels

    @property
    def output_device(self) -> str | None:
        return self._inner.output_device

    @property
    def underruns(self) -> int:
        return self._inner.underruns

    @property
    def output_latency_s(self) -> float:
        return self._inner.output_latency_s

    def start(self, render: RenderFn) -> None:
        self.probe = CallbackProbe(render, self._capacity)
        self._inner.start(self.probe)

    def close(self) -> None:
        self._inner.close()


def busy_json(stop: threading.Event, calls: list[int]) -> None:
    """Keep the GIL busy: encode and decode state messages like a busy web server."""
    state = {
        "type": "state",
        "levels": [0.1] * 8,
        "contacts": [{"contact": f"c{k}", "x_cm": 1.9, "y_cm": 0.1 * k} for k in range(40)],
    }
    while not stop.is_set():
        json.loads(json.dumps(state))
        calls[0] += 1


def play_scene(engine: Any, seconds: float) -> None:
    """8 pattern voices (restarted as they end) and 8 contacts moving at 90 Hz."""
    began = time.monotonic()
    ends_s: list[float] = []
    started = 0
    for k in range(8):
        engine.contact_down("bench", f"c{k}", 0.4 * k, 1.0 + 1.6 * k, intensity=0.3)
    while (now_s := time.monotonic()) - began < seconds:
        ends_s = [end_s for end_s in ends_s if end_s > now_s]
        while len(ends_s) < 8:
            job = engine.schedule(pt.preset(PATTERN_PRESETS[started % len(PATTERN_PRESETS)]))
            ends_s.append(now_s + job.duration_s + 0.05)
            started += 1
        phase = now_s - began
        for k in range(8):
            y_cm = 7.2 + 6.0 * np.sin(phase + k)
            engine.contact_move("bench", f"c{k}", 1.9 + 1.5 * np.cos(phase + k), y_cm)
        time.sleep(1 / 90)


def underrun_run(seconds: float, *, json_thread: bool, own_process: bool) -> dict[str, Any]:
    """One run on a private ``jackd -p 128``; the JSON thread runs in this process."""
    import sounddevice  # noqa: F401 (PortAudio is initialised before the server starts)

    from phantomtouch.engine.process import ProcessEngine
    from phantomtouch.output.soundcard import SinkSpec, SoundDeviceSink
    from tests.support.jack import JackServer, JackXrunCounter

    device = pt.DeviceProfile.default().model_copy(update={"block_frames": 128})
    period_s = 128 / 48000
    probe: CallbackProbe | None = None
    with JackServer(period_frames=128) as server:
        xruns = JackXrunCounter(server)
        engine: Any
        if own_process:
            engine = ProcessEngine(device, SinkSpec("sounddevice", "system"))
        else:
            sink = ProbedSink(SoundDeviceSink(device, "system"), int(seconds / period_s * 1.2))
            engine = Engine(device, sink)
        stop = threading.Event()
        calls = [0]
        worker = threading.Thread(target=busy_json, args=(stop, calls), daemon=True)
        engine.start()
        if json_thread:
            worker.start()
        play_scene(engine, seconds)
        status = engine.status()
        stop.set()
        if json_thread:
            worker.join()
        engine.close()
        jack_xruns = xruns.close()
        if not own_process:
            probe = sink.probe
    result: dict[str, Any] = {
        "seconds": seconds,
        "underruns": status.underruns,
        "jack_xruns": jack_xruns,
        "json_calls_per_s": calls[0] / seconds,
        "switch_interval_ms": sys.getswitchinterval() * 1e3,
        "render_load_p99": status.render_load_p99,
        "render_load_max": status.render_load_max,
    }
    if probe is not None:  # the callback runs in this process: where did deadlines go?
        n = min(probe.count, len(probe.starts))
        gaps = np.diff(probe.starts[:n])
        durations = probe.durations[:n]
        result.update(
            {
                "callbacks": probe.count,
                "expected_callbacks": round(seconds / period_s),
                "gaps_over_1.5_periods": int(np.sum(gaps > 1.5 * period_s)),
                "gap_max_ms": float(gaps.max() * 1e3),
                "render_p50_of_period": float(np.percentile(durations, 50) / period_s),
                "render_p99_of_period": float(np.percentile(durations, 99) / period_s),
            }
        )
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, default=3000, help="blocks timed per scene")
    parser.add_argument("--seconds", type=float, default=60.0, help="the JACK run, s")
    parser.add_argument(
        "--diagnose-seconds", type=float, default=20.0, help="each diagnostic run, s (0: none)"
    )
    parser.add_argument(
        "--block-frames", type=int, default=256, help="block of the render benchmark (16-4096)"
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()
    if not 16 <= args.block_frames <= 4096:
        parser.error(f"--block-frames {args.block_frames}: must be between 16 and 4096")
    render_rows = render_benchmark(args.blocks, args.block_frames)
    runs = {
        "ProcessEngine, JSON thread": underrun_run(args.seconds, json_thread=True, own_process=True)
    }
    if args.diagnose_seconds > 0:
        runs["Engine, JSON thread"] = underrun_run(
            args.diagnose_seconds, json_thread=True, own_process=False
        )
        runs["Engine, no JSON thread"] = underrun_run(
            args.diagnose_seconds, json_thread=False, own_process=False
        )
    if args.json:
        print(json.dumps({"render": render_rows, "underruns": runs}, indent=2))
        return
    period_ms = args.block_frames / 48
    print(
        f"Render time of one {args.block_frames}-frame block (period {period_ms:.3f} ms; "
        "targets: p99 <= 10 % at 16 voices, <= 25 % at 64)"
    )
    header = f"{'scene':34} {'wall p50':>9} {'wall p99':>9} {'p99/period':>10}"
    print(header + f" {'cpu p50':>8} {'cpu p99':>8} {'p99/period':>10} {'p50/copy':>8}")
    for row in render_rows:
        print(
            f"{row['scene']:34} {row['wall_p50_us']:7.1f}us {row['wall_p99_us']:7.1f}us "
            f"{row['wall_p99_of_period']:10.1%} {row['cpu_p50_us']:6.1f}us "
            f"{row['cpu_p99_us']:6.1f}us {row['cpu_p99_of_period']:10.1%} "
            f"{row['wall_p50_in_copies']:8.0f}"
        )
    print()
    print("Underruns at 128-frame blocks on JACK's dummy driver (target 0)")
    for name, run in runs.items():
        line = (
            f"{name:28} {run['seconds']:4.0f} s: underruns {run['underruns']:5d} "
            f"(JACK xruns {run['jack_xruns']}), JSON calls/s {run['json_calls_per_s']:.0f}"
        )
        line += (
            f"; engine's render load p99/max over its last 4096 blocks "
            f"{run['render_load_p99']:.0%}/{run['render_load_max']:.0%}"
        )
        if "callbacks" in run:
            line += (
                f"; callbacks {run['callbacks']}/{run['expected_callbacks']}, gaps > 1.5 "
                f"periods {run['gaps_over_1.5_periods']}, longest {run['gap_max_ms']:.1f} ms, "
                f"render p50/p99 {run['render_p50_of_period']:.0%}/"
                f"{run['render_p99_of_period']:.0%} of the period"
            )
        print(line)


if __name__ == "__main__":
    main()
