"""The sample clock: frames to server time and back, jitter and stalls."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch.engine.clock import RESYNC_S, SampleClock

RATE = 48000
BLOCK = 256
PERIOD_S = BLOCK / RATE


def test_frames_and_times_are_inverse_and_include_the_output_latency() -> None:
    clock = SampleClock(RATE, now_s=100.0)
    clock.output_latency_s = 0.004
    assert clock.time_at(0) == pytest.approx(100.004)
    assert clock.time_at(RATE) == pytest.approx(101.004)
    assert clock.frames_at(101.004) == RATE
    for frame in (0, 1, 12345, 10**9):
        assert clock.frames_at(clock.time_at(frame)) == frame


def test_late_callbacks_barely_move_the_clock_early_ones_move_it_at_once(
    rng: np.random.Generator,
) -> None:
    clock = SampleClock(RATE, now_s=0.0)
    for block in range(1, 2000):
        jitter_s = float(rng.uniform(0.0, 0.002))
        clock.observe(block * BLOCK, block * PERIOD_S + jitter_s)
    # callbacks are never early: the clock stays near the earliest arrivals
    assert clock.time_at(0) == pytest.approx(0.0, abs=0.0005)
    clock.observe(2000 * BLOCK, 2000 * PERIOD_S - 0.001)  # an early one: follow at once
    assert clock.time_at(2000 * BLOCK) == pytest.approx(2000 * PERIOD_S - 0.001)


def test_a_stalled_stream_re_anchors_the_clock() -> None:
    clock = SampleClock(RATE, now_s=0.0)
    clock.observe(BLOCK, PERIOD_S)
    clock.observe(2 * BLOCK, 2 * PERIOD_S + RESYNC_S + 0.5)
    assert clock.time_at(2 * BLOCK) == pytest.approx(2 * PERIOD_S + RESYNC_S + 0.5)
    assert clock.frames_at(2 * PERIOD_S + RESYNC_S + 0.5 + 1.0) == 2 * BLOCK + RATE
