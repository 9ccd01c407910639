"""Pattern voices: render-ahead gives the block renderer's samples; untouched channels."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import Engine
from phantomtouch.engine.local_audio import RENDER_AHEAD_RINGS
from phantomtouch.engine.voices import PatternVoice, RingPool, Workspace
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.renderer import plan

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames


def pattern(k: int) -> TouchPattern:
    carriers = [{"kind": "sine", "freq_hz": 50 + k}, {"kind": "noise", "seed": k}]
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[0.1 * (k % 38), 14.0], [3.8, 0.3 * k]]},
            "speed_cm_s": 40.0 + k,
            "fade_in_s": 0.01,
            "fade_out_s": 0.01,
            "intensity": 0.01,
            "carrier": carriers[k % 2],
        }
    )


def play(render_ahead_frames: int, voices: int) -> np.ndarray:
    sink = CaptureSink(DEVICE)
    with Engine(
        DEVICE,
        sink,
        render_ahead_frames=render_ahead_frames,
        max_voices=voices,
        prerender_max_s=0.0,  # these short strokes render in the callback, not beforehand
    ) as engine:
        jobs = [engine.schedule(pattern(k), start_frame=97 * k) for k in range(voices)]
        for job in jobs[::5]:
            sink.pull(1)
            engine.stop(job.job_id)  # some are stopped while rendering ahead
        sink.pull(max(j.start_frame + j.frames for j in jobs) // BLOCK + 1)
        return sink.recording()


@pytest.mark.parametrize("voices", [3, RENDER_AHEAD_RINGS + 8])
def test_rendering_ahead_gives_the_same_samples_as_rendering_each_block(voices: int) -> None:
    np.testing.assert_array_equal(play(2048, voices), play(0, voices))


def test_a_voice_rendered_ahead_equals_the_offline_render_whatever_the_chunk() -> None:
    reference = render(pattern(3), DEVICE)
    for chunk in (BLOCK, 1000, 4096, 8192):
        sink = CaptureSink(DEVICE)
        with Engine(DEVICE, sink, render_ahead_frames=chunk, prerender_max_s=0.0) as engine:
            engine.schedule(pattern(3), start_frame=5)
            recording = sink.pull(len(reference) // BLOCK + 1)
        np.testing.assert_array_equal(recording[5 : 5 + len(reference)], reference)


def test_a_voice_rendered_block_by_block_touches_only_the_channels_its_gains_drive() -> None:
    # (a voice with a ring adds whole-width frames, zeros where it drives nothing: one
    # contiguous add; the next test checks that it adds exactly its samples)
    still = TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[0.0, 4.8]]}, "duration_s": 1.3}
    )
    voice = PatternVoice(plan(still, DEVICE), job=1, release_frames=100)
    voice.begin(0, RingPool(1, 0, DEVICE.channels))
    work = Workspace(BLOCK, DEVICE.channels)
    mix = np.full((BLOCK, DEVICE.channels), -0.0, dtype=np.float32)  # -0.0 + 0.0 is +0.0
    for block in range(20):
        voice.render(mix, block * BLOCK, work)
    assert np.all(np.signbit(np.delete(mix, 1, axis=1)))  # never written
    assert np.any(mix[:, 1])


def test_a_voice_adds_exactly_its_samples_to_what_the_mix_holds(rng: np.random.Generator) -> None:
    # A 1D stroke drives two rows (channels 1, 2, 5, 6 and so on): wider than half the
    # channels, so the voice adds all of them; the others must keep their values exactly.
    stroke = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 0.0], [1.9, 14.4]]},
            "mode": "1d",
            "speed_cm_s": 30.0,
            "fade_in_s": 0.05,
            "fade_out_s": 0.05,
        }
    )
    reference = render(stroke, DEVICE)  # the default device: no calibration, no clipping
    voice = PatternVoice(plan(stroke, DEVICE), job=1, release_frames=100)
    voice.begin(0, RingPool(1, 4096, DEVICE.channels))
    work = Workspace(BLOCK, DEVICE.channels)
    blocks = len(reference) // BLOCK
    base = rng.uniform(-0.5, 0.5, (blocks * BLOCK, DEVICE.channels)).astype(np.float32)
    mixed = base.copy()
    for block in range(blocks):
        voice.render(mixed[block * BLOCK : (block + 1) * BLOCK], block * BLOCK, work)
    np.testing.assert_array_equal(mixed, base + reference[: blocks * BLOCK])
    # some blocks span more than half the channels yet leave some of them silent
    driven = reference[: blocks * BLOCK].reshape(blocks, BLOCK, -1).any(axis=1)
    span = DEVICE.channels - np.argmax(driven[:, ::-1], axis=1) - np.argmax(driven, axis=1)
    assert np.any((2 * span > DEVICE.channels) & ~driven.all(axis=1))
