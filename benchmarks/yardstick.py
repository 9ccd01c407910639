"""The yardstick the real-time benchmarks state the callback's time in: one numpy copy of a
128 x 8 float32 block, timed in this process.

Each timing covers 100 copies in a loop, so the clock's own cost (a ``perf_counter`` call
and storing its result take about as long as the copy) is not counted as part of one copy;
the yardstick is the median of 2,000 such timings.

The machine's speed is not steady, and the copy shows it: on one 2-core virtual machine,
timed 40 times half a second apart while nothing else ran, it took 0.40 µs or 0.68-1.08 µs
as it came, and in 15 timings back to back, each after half a second of busy looping,
0.67-0.83 µs for the first 9 and 0.40 µs from then on. A figure in yardsticks is therefore
only as good as the copy's timing beside it: ``bench_realtime.py`` times it in each
scenario's rest and prints the range.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

FRAMES = 128
CHANNELS = 8


def block_copy_s(timings: int = 2000, copies: int = 100) -> float:
    """One ``block.copy()`` of a ``FRAMES`` x ``CHANNELS`` float32 block, s (median)."""
    block = np.zeros((FRAMES, CHANNELS), dtype=np.float32)
    samples = []
    for _ in range(timings):
        began = time.perf_counter()
        for _ in range(copies):
            block.copy()
        samples.append((time.perf_counter() - began) / copies)
    return statistics.median(samples)
