"""Admission by the render budget, and voice stealing that fades out without a click."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch import DeviceProfile, EngineBusyError, TouchPattern, render
from phantomtouch.engine import Engine
from phantomtouch.engine.front import STEAL_FADE_S
from phantomtouch.engine.render_budget import CHURN_SHARE, CHURN_WINDOW_S
from phantomtouch.output.sinks import CaptureSink

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
FADE = round(STEAL_FADE_S * DEVICE.sample_rate_hz)
COST = 0.125  # a power of two: budget / cost is exact in binary


def hold(x_cm: float, y_cm: float, *, intensity: float = 0.5, seconds: float = 2.0) -> TouchPattern:
    """A steady sine at one point (no fades): its samples are known in closed form."""
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[x_cm, y_cm]]},
            "duration_s": seconds,
            "fade_in_s": 0,
            "fade_out_s": 0,
            "intensity": intensity,
        }
    )


def pull_to(sink: CaptureSink, frame: int) -> np.ndarray:
    missing = frame - sink.frames
    if missing > 0:
        sink.pull(-(-missing // BLOCK))
    return sink.recording()


@pytest.mark.parametrize(("budget", "capacity"), [(0.5, 4), (0.625, 5), (1.0, 8)])
def test_refuse_admits_exactly_the_voices_the_budget_pays_for(budget: float, capacity: int) -> None:
    sink = CaptureSink(DEVICE)
    with Engine(
        DEVICE, sink, voice_cost=COST, render_budget=budget, voice_policy="refuse"
    ) as engine:
        assert engine.voice_capacity == capacity
        assert engine.status().voice_capacity == capacity
        for k in range(capacity):
            engine.schedule(hold(0.0, 4.8 * (k % 4)), start_frame=10 * BLOCK)
        with pytest.raises(EngineBusyError, match=f"the voice budget allows {capacity}"):
            engine.schedule(hold(0.0, 0.0), start_frame=10 * BLOCK)
        # a job that starts once the others are over is admitted
        later = 10 * BLOCK + round(2.0 * DEVICE.sample_rate_hz)
        engine.schedule(hold(0.0, 0.0), start_frame=later)


def test_max_voices_caps_what_the_budget_allows() -> None:
    with Engine(DEVICE, CaptureSink(DEVICE), voice_cost=1e-4, max_voices=7) as engine:
        assert engine.voice_capacity == 7


def test_steal_oldest_fades_the_oldest_out_over_the_steal_ramp() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, voice_cost=COST, render_budget=COST) as engine:  # one voice
        assert engine.voice_capacity == 1
        old = hold(0.0, 0.0)  # actuator 1 alone: channel 0
        new = hold(3.8, 14.4)  # actuator 8 alone: channel 7
        first = engine.schedule(old, start_frame=0)
        steal_at = 20 * BLOCK + 37
        pull_to(sink, 10 * BLOCK)
        second = engine.schedule(new, start_frame=steal_at)
        recording = pull_to(sink, steal_at + FADE + 4 * BLOCK)
        stolen = engine.job_state(first.job_id)
        assert stolen is not None and stolen.state == "stopped"
        assert stolen.end_frame == steal_at + FADE - 1
        assert engine.job_state(second.job_id).state == "playing"  # type: ignore[union-attr]
    reference_old = render(old, DEVICE)[:, 0]
    played = recording[:, 0]
    # up to the steal, the old voice is exactly its offline render
    np.testing.assert_array_equal(played[:steal_at], reference_old[:steal_at])
    # then it fades linearly over FADE frames: gain (R + L - 1 - f) / L, no larger step
    frames = np.arange(steal_at, steal_at + FADE)
    gains = np.clip((steal_at + FADE - 1 - frames) / FADE, 0.0, 1.0).astype(np.float32)
    np.testing.assert_allclose(
        played[steal_at : steal_at + FADE], reference_old[frames] * gains, rtol=0, atol=1e-6
    )
    assert not np.any(played[steal_at + FADE - 1 :])
    amplitude = np.abs(reference_old).max()
    carrier_step = np.abs(np.diff(reference_old)).max()
    assert np.abs(np.diff(played)).max() <= carrier_step + amplitude / FADE + 1e-6
    # the new voice plays exactly, from its frame
    reference_new = render(new, DEVICE)[:, 7]
    end = len(recording)
    np.testing.assert_array_equal(recording[steal_at:end, 7], reference_new[: end - steal_at])


def test_steal_quietest_takes_the_quietest_sounding_job() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(
        DEVICE, sink, voice_cost=COST, render_budget=3 * COST, voice_policy="steal-quietest"
    ) as engine:
        jobs = [
            engine.schedule(hold(0.0, 4.8 * k, intensity=level), start_frame=k * BLOCK)
            for k, level in enumerate([0.6, 0.2, 0.9])
        ]
        pull_to(sink, 8 * BLOCK)
        newest = engine.schedule(hold(3.8, 0.0, intensity=0.1), start_frame=10 * BLOCK)
        pull_to(sink, 12 * BLOCK)
        states = [engine.job_state(job.job_id).state for job in jobs]  # type: ignore[union-attr]
        assert states == ["playing", "stopped", "playing"]
        assert engine.job_state(newest.job_id).state == "playing"  # type: ignore[union-attr]


def test_a_job_that_starts_later_steals_nothing_and_is_refused_if_it_cannot() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, voice_cost=COST, render_budget=COST) as engine:
        engine.schedule(hold(0.0, 0.0), start_frame=100 * BLOCK)
        # the only job that would overlap has not started by this job's start: nothing
        # sounds at that frame that could be stolen
        with pytest.raises(EngineBusyError, match="voice budget"):
            engine.schedule(hold(3.8, 0.0), start_frame=50 * BLOCK)


def test_a_job_planned_across_a_stop_is_void_and_never_plays() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        arrived = engine.stop_count  # a request arrives, then is planned ...
        engine.stop_all()  # ... while a stop comes
        job = engine.schedule(hold(0.0, 0.0), start_frame=2 * BLOCK, stop_count=arrived)
        recording = pull_to(sink, 20 * BLOCK)
        state = engine.job_state(job.job_id)
        assert state is not None and state.state == "stopped"
        assert not np.any(recording)
        # a request that arrives after the stop plays
        after = engine.schedule(
            hold(0.0, 0.0), start_frame=30 * BLOCK, stop_count=engine.stop_count
        )
        recording = pull_to(sink, 40 * BLOCK)
        assert engine.job_state(after.job_id).state == "playing"  # type: ignore[union-attr]
        assert np.any(recording[30 * BLOCK :])


def test_voices_beginning_at_once_are_spread_over_blocks_within_the_start_budget() -> None:
    sink = CaptureSink(DEVICE)
    # a voice's first block costs 0.1 of a block: START_SHARE (0.2) lets 2 begin per block
    with Engine(DEVICE, sink, voice_cost=1e-4, start_cost=0.1) as engine:
        assert engine.starts_per_block == 2
        delay_blocks = -(-round(0.02 * DEVICE.sample_rate_hz) // BLOCK)  # MAX_START_DELAY_S
        starts = [
            engine.schedule(hold(0.0, 0.0)).start_frame for _ in range(2 * (delay_blocks + 1))
        ]
        first_block = starts[0] // BLOCK  # the next block (nothing has played yet)
        expected = [(first_block + k // 2) * BLOCK for k in range(len(starts))]
        assert starts == expected
        with pytest.raises(EngineBusyError, match="2 pattern voices begin in every block"):
            engine.schedule(hold(0.0, 0.0))
        # a job for a given frame keeps it, or is refused when its block is full
        at = (first_block + 50) * BLOCK + 17
        engine.schedule(hold(0.0, 0.0), start_frame=at)
        engine.schedule(hold(0.0, 0.0), start_frame=at + 1)
        with pytest.raises(EngineBusyError, match="already begin in the block"):
            engine.schedule(hold(0.0, 0.0), start_frame=at + 2)
        recording = pull_to(sink, (first_block + delay_blocks + 2) * BLOCK)
    # each voice began at its frame: the first block sounds, nothing before it
    assert not np.any(recording[: first_block * BLOCK])
    assert np.any(recording[first_block * BLOCK : (first_block + 1) * BLOCK])


def test_touches_begin_no_faster_than_the_churn_share_pays_for() -> None:
    sink = CaptureSink(DEVICE)
    touch = hold(0.0, 0.0)
    # a voice's first frames cost 0.1 of a block; the account holds CHURN_SHARE (0.15) of
    # a block for 0.1 s of blocks, 2.8125 blocks' worth: 28 touches, then refusals (touches
    # rendered in the callback: prerendered they cost nothing there, tests/engine/test_prerender.py)
    window = CHURN_SHARE * CHURN_WINDOW_S * DEVICE.sample_rate_hz / BLOCK
    with Engine(DEVICE, sink, voice_cost=1e-4, start_cost=0.1, prerender_max_s=0.0) as engine:
        accepted = 0
        with pytest.raises(EngineBusyError, match="touches begin faster"):
            while True:
                engine.schedule(touch, start_frame=(100 + accepted) * BLOCK)
                accepted += 1
        assert accepted == int(window / 0.1) == 28
        # the account drains by CHURN_SHARE of a block per block played
        pull_to(sink, 2 * BLOCK)  # 0.3 blocks paid: three more touches fit, not four
        for k in range(3):
            engine.schedule(touch, start_frame=(200 + k) * BLOCK)
        with pytest.raises(EngineBusyError, match="touches begin faster"):
            engine.schedule(touch, start_frame=203 * BLOCK)
