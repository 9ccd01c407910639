"""A clip's transients rendered once per plan (renderer/clip.py, ``TransientTable``): the
table holds, frame by frame, the sum of the windowed sines docs/algorithms.md (sec. 11)
defines, and a block reads it without a loop over the transients."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from phantomtouch.renderer.clip import TRANSIENT_CYCLES, ClipSource, TransientTable, clip_freq_hz
from phantomtouch.schema.clip import MAX_CLIP_TRANSIENTS, HapticClip

FS = 48_000


def clip_with(transients: list[dict[str, float]], duration_s: float = 1.0) -> HapticClip:
    return HapticClip.model_validate(
        {
            "duration_s": duration_s,
            "amplitude": [{"t_s": 0.0, "value": 0.0}],
            "transients": transients,
        }
    )


def direct(clip: HapticClip, frames: int) -> np.ndarray:
    """The transients, one by one, at frames 0 .. frames - 1 (the naive reference)."""
    t_s = np.arange(frames) / FS
    out = np.zeros(frames)
    for tr in clip.transients:
        freq_hz = float(clip_freq_hz(tr.frequency))
        length_s = TRANSIENT_CYCLES / freq_hz
        local = t_s - tr.t_s
        inside = (local >= 0) & (local < length_s)
        u = local[inside]
        out[inside] += (
            tr.amplitude
            * (0.5 - 0.5 * np.cos(2 * np.pi * u / length_s))
            * np.sin(2 * np.pi * freq_hz * u)
        )
    return out


def test_the_table_is_the_sum_of_the_transients(rng: np.random.Generator) -> None:
    times = np.sort(rng.uniform(0.0, 0.9, 40))
    clip = clip_with(
        [
            {"t_s": float(t), "amplitude": float(a), "frequency": float(f)}
            for t, a, f in zip(times, rng.uniform(0, 1, 40), rng.uniform(0, 1, 40), strict=True)
        ]
    )
    played = ClipSource(clip, FS).block(0, FS)
    # the table is float32: 1e-6 of the largest sum
    np.testing.assert_allclose(played, direct(clip, FS), atol=1e-6)


def test_a_thousand_transients_at_one_time_are_one_table_run() -> None:
    click = {"t_s": 0.0, "amplitude": 0.001, "frequency": 0.0}
    many = TransientTable(clip_with([click] * MAX_CLIP_TRANSIENTS), FS)
    one = ClipSource(clip_with([click]), FS).block(0, 4096)
    assert many.run_first.size == 1  # one span: 60 ms, whatever the count
    played = ClipSource(clip_with([click] * MAX_CLIP_TRANSIENTS), FS, transients=many).block(
        0, 4096
    )
    np.testing.assert_allclose(
        played, MAX_CLIP_TRANSIENTS * one.astype(np.float64), rtol=1e-5, atol=1e-7
    )


def test_more_transients_than_the_cap_are_refused_naming_the_field() -> None:
    click = {"t_s": 0.0, "amplitude": 1.0, "frequency": 0.0}
    with pytest.raises(ValidationError, match="transients"):
        clip_with([click] * (MAX_CLIP_TRANSIENTS + 1))


def test_a_looped_clip_of_a_fractional_number_of_frames_repeats_its_transients() -> None:
    """Each pass plays the table from the pass's start; blocks of any size agree."""
    duration_s = 0.10001  # 4800.48 frames
    clip = clip_with([{"t_s": 0.02, "amplitude": 1.0, "frequency": 1.0}], duration_s)
    source = ClipSource(clip, FS, loop=True)
    whole = source.block(0, 3 * 4801)
    pieces = np.concatenate(
        [ClipSource(clip, FS, loop=True).block(at, 333) for at in range(0, 3 * 4801, 333)]
    )
    np.testing.assert_array_equal(pieces[: len(whole)], whole)
    first = whole[:4800]
    second = whole[4800 : 2 * 4800]
    # the second pass starts 0.48 frame early: a line between frames, close to the first
    np.testing.assert_allclose(second, first, atol=0.05)
    assert np.abs(first).max() > 0.5
