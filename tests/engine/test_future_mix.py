"""The future-mix ring: prerendered voices summed ahead of the blocks that play them.

What the engine plays is checked against ``render()`` of each pattern, summed in float32
in the order the voices began (the order the callback adds them), with the release fade
``(R + L - 1 - f) / L`` of a stopped or stolen voice: bit for bit, at 128- and 64-frame
blocks, with a stop and a steal that land inside frames the ring has summed already,
and with a voice whose samples are NaN inside the ring.
"""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import Engine
from phantomtouch.engine.front import STEAL_FADE_S
from phantomtouch.engine.future_mix import AHEAD_FRAMES
from phantomtouch.output.sinks import CaptureSink
from tests.engine.test_voice_guard import nan_plan

PROFILE = DeviceProfile.default()
RATE = PROFILE.sample_rate_hz
STOP_FADE = round(0.08 * RATE)  # ContactSettings.release_s: a stop's fade
STEAL_FADE = round(STEAL_FADE_S * RATE)


def tap(x_cm: float, y_cm: float, seconds: float) -> TouchPattern:
    """A short still touch (prerendered: at most 1 s), low enough that four summed stay
    under the limiter's threshold."""
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[x_cm, y_cm]]},
            "duration_s": seconds,
            "fade_in_s": 0.01,
            "fade_out_s": 0.05,
            "intensity": 0.2,
            "carrier": {"kind": "sine", "freq_hz": 150.0},
        }
    )


def summed(frames: int, parts: list[tuple[int, np.ndarray, int | None, int]]) -> np.ndarray:
    """The float32 sum of ``(start, samples, release_frame, fade_frames)`` in order, each
    faded from its release frame by ``(R + L - 1 - f) / L`` in float32, clipped to [0, 1]."""
    total = np.zeros((frames, PROFILE.channels), dtype=np.float32)
    for start, samples, release, fade in parts:
        played = samples = samples[: frames - start]  # what the recording holds
        if release is not None:
            frame = np.arange(start, start + len(samples))
            gains = np.float32(release + fade - 1) - frame.astype(np.float32)
            gains = np.clip(gains * np.float32(1.0 / fade), 0.0, 1.0).astype(np.float32)
            played = samples * gains[:, None]
        total[start : start + len(samples)] += played
    return total


def pull_to(sink: CaptureSink, block: int, frame: int) -> None:
    missing = frame - sink.frames
    if missing > 0:
        sink.pull(-(-missing // block))


@pytest.mark.parametrize("block", [128, 64])
def test_the_ring_plays_render_bit_for_bit_through_a_stop_and_a_steal(block: int) -> None:
    sink = CaptureSink(PROFILE, period_frames=block)
    patterns = [tap(0.0, 0.0, 0.5), tap(3.8, 4.8, 0.4), tap(0.0, 9.6, 0.3), tap(3.8, 14.4, 0.45)]
    with Engine(PROFILE, sink, voice_cost=1e-4, max_voices=4) as engine:
        scheduler = engine.core.scheduler
        jobs = [
            engine.schedule(pattern, start_frame=3 * block + 17 + 700 * k)
            for k, pattern in enumerate(patterns)
        ]
        stop_at = 3 * block + 4000 // block * block  # a block boundary, the 2nd voice sounding
        pull_to(sink, block, stop_at)
        assert len(scheduler.future.voices) == 4  # every voice in the ring
        assert scheduler.future.summed_to > stop_at  # the stop lands in frames summed ahead
        assert engine.stop(jobs[1].job_id)
        while scheduler.future.summed_to <= sink.frames + 2 * block:  # a block or two on
            sink.pull(1)
        steal_at = sink.frames + block + 5  # the oldest (the first) is stolen here,
        assert scheduler.future.summed_to > steal_at  # inside frames summed ahead too
        newcomer = tap(1.9, 7.2, 0.2)
        late = engine.schedule(newcomer, start_frame=steal_at)
        pull_to(sink, block, steal_at + len(render(newcomer, PROFILE)) + 2 * block)
        states = [engine.job_state(job.job_id) for job in jobs]
        status = engine.status()
    recording = sink.recording()
    assert states[0] is not None and states[0].state == "stopped"
    assert states[0].end_frame == steal_at + STEAL_FADE - 1
    assert states[1] is not None and states[1].end_frame == stop_at + STOP_FADE - 1
    assert status.limited_blocks == 0 and status.dc_blocked_blocks == 0
    parts: list[tuple[int, np.ndarray, int | None, int]] = [
        (jobs[0].start_frame, render(patterns[0], PROFILE), steal_at, STEAL_FADE),
        (jobs[1].start_frame, render(patterns[1], PROFILE), stop_at, STOP_FADE),
        (jobs[2].start_frame, render(patterns[2], PROFILE), None, 1),
        (jobs[3].start_frame, render(patterns[3], PROFILE), None, 1),
        (late.start_frame, render(newcomer, PROFILE), None, 1),
    ]
    np.testing.assert_array_equal(recording, summed(len(recording), parts))


def test_a_nan_voice_in_the_ring_is_silenced_alone_and_the_others_play_bit_for_bit() -> None:
    block = PROFILE.block_frames
    sink = CaptureSink(PROFILE)
    good = [tap(0.0, 0.0, 0.5), tap(3.8, 14.4, 0.6)]
    with Engine(PROFILE, sink) as engine:
        jobs = [
            engine.schedule(pattern, start_frame=2 * block + 300 * k)
            for k, pattern in enumerate(good)
        ]
        nan_at = 2 * block + AHEAD_FRAMES // 2 + 11  # inside frames the ring has summed
        pull_to(sink, block, nan_at - block)
        assert engine.core.scheduler.future.summed_to > nan_at
        engine.schedule(nan_plan(0.5, 0.05), start_frame=nan_at)  # prerendered: its NaN in the ring
        pull_to(sink, block, jobs[1].start_frame + jobs[1].frames + 2 * block)
        status = engine.status()
    recording = sink.recording()
    assert status.nonfinite_voices == 1 and status.muted_blocks == 0
    assert np.isfinite(recording).all()
    parts: list[tuple[int, np.ndarray, int | None, int]] = [
        (job.start_frame, render(pattern, PROFILE), None, 1)
        for job, pattern in zip(jobs, good, strict=True)
    ]
    np.testing.assert_array_equal(recording, summed(len(recording), parts))
