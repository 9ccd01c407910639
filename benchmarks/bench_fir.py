"""Cost of the calibration FIR: partitioned FFT convolution against the direct form.

Both filter the same 8 channels of float32 noise through 4096-tap filters (the largest
a profile may hold), in blocks of the engine's size (256 frames) and of the offline
render (65536 frames), in the same run:

- ``PartitionedFir`` (what :class:`~phantomtouch.renderer.output.OutputStage` runs);
- the direct form, ``scipy.signal.lfilter`` with its state carried between blocks (what
  the output stage ran before);
- a numpy copy of the signal (a memcpy) as the machine's yardstick.

Reported: CPU milliseconds per second of 8-channel 48 kHz audio (best of ``--repeats``,
``time.process_time``; the two forms take turns, so a busy neighbour slows both), the
ratio direct / partitioned, and the largest difference between the two outputs in units
of full scale.

Run: ``python benchmarks/bench_fir.py [--seconds S] [--json]``. Target (issue): the
partitioned form >= 8x cheaper, equal within 1e-6 of full scale.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import time
from collections.abc import Callable

import numpy as np
from scipy import signal

from phantomtouch.renderer.fir import PartitionedFir
from phantomtouch.schema import limits

FS = 48000
CHANNELS = 8


def cpu_s(fn: Callable[[], object]) -> float:
    start = time.process_time()
    fn()
    return time.process_time() - start


def best_of(fn: Callable[[], object], repeats: int) -> float:
    return min(cpu_s(fn) for _ in range(repeats))


def best_of_alternating(
    first: Callable[[], object], second: Callable[[], object], repeats: int
) -> tuple[float, float]:
    """Best CPU time of each of two functions, run in turns."""
    best = [math.inf, math.inf]
    for _ in range(repeats):
        best[0] = min(best[0], cpu_s(first))
        best[1] = min(best[1], cpu_s(second))
    return best[0], best[1]


def partitioned(taps: np.ndarray, x: np.ndarray, block: int) -> np.ndarray:
    out = x.copy()
    fir = PartitionedFir(taps)
    for start in range(0, len(out), block):
        fir.process(out[start : start + block])
    return out


def direct(taps: np.ndarray, x: np.ndarray, block: int) -> np.ndarray:
    out = x.copy()
    state = [np.zeros(taps.shape[1] - 1) for _ in range(CHANNELS)]
    for start in range(0, len(out), block):
        for ch in range(CHANNELS):
            y, state[ch] = signal.lfilter(
                taps[ch], 1.0, out[start : start + block, ch], zi=state[ch]
            )
            out[start : start + block, ch] = y
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rng = np.random.default_rng(7)
    n_taps = limits.MAX_FIR_TAPS
    taps = rng.standard_normal((CHANNELS, n_taps)) * np.exp(-np.arange(n_taps) / 1000.0)
    taps /= np.abs(taps).sum(axis=1, keepdims=True)  # |h|_1 = 1: full scale in, within out
    x = rng.uniform(-1.0, 1.0, size=(int(args.seconds * FS), CHANNELS)).astype(np.float32)
    copy_s = best_of(lambda: x.copy(), args.repeats * 10)
    rows = []
    for block in (256, 65536):
        fast = partitioned(taps, x, block)
        slow = direct(taps, x, block)
        fast_s, slow_s = best_of_alternating(
            functools.partial(partitioned, taps, x, block),
            functools.partial(direct, taps, x, block),
            args.repeats,
        )
        rows.append(
            {
                "block_frames": block,
                "partitioned_ms_per_s": 1000 * fast_s / args.seconds,
                "direct_ms_per_s": 1000 * slow_s / args.seconds,
                "ratio": slow_s / fast_s,
                "max_difference_full_scale": float(np.abs(fast - slow).max()),
            }
        )
    result = {"taps": n_taps, "copy_ms_per_s": 1000 * copy_s / args.seconds, "rows": rows}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"{n_taps} taps, {CHANNELS} channels; numpy copy {result['copy_ms_per_s']:.3f} ms/s")
    for row in rows:
        print(
            f"block {row['block_frames']:6d}: partitioned {row['partitioned_ms_per_s']:7.1f} ms/s"
            f"  direct {row['direct_ms_per_s']:7.1f} ms/s  ratio {row['ratio']:.1f}x"
            f"  max |diff| {row['max_difference_full_scale']:.2e}"
        )


if __name__ == "__main__":
    main()
