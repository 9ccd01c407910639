"""The block renderer of one pattern: carrier x gains, gain grid and ramps, add and into."""

from __future__ import annotations

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.renderer.carriers import make_source
from phantomtouch.renderer.trajectory import control_gains, modulation_at
from phantomtouch.renderer.voice import PatternRenderer, gain_block
from phantomtouch.schema import DeviceProfile, TouchPattern

FS = 48000
STROKE = {
    "path": {
        "kind": "arc",
        "start_cm": [3.8, 12.0],
        "through_cm": [0.0, 7.2],
        "end_cm": [3.8, 2.4],
    },
    "duration_s": 0.25,
    "fade_in_s": 0.05,
    "fade_out_s": 0.05,
    "modulation": {"index": 0.8, "freq_hz": "stroke"},
}
# Products of float32 carrier samples and float32 gains: about 1e-7 of full scale.
FLOAT32 = 1e-6


def plan_of(carrier: dict | None = None, **device_fields) -> pt.Plan:
    touch = TouchPattern.model_validate({**STROKE, "carrier": carrier or {"kind": "sine"}})
    return pt.plan(touch, DeviceProfile.default().model_copy(update=device_fields))


def carrier_of(resolved: pt.Plan) -> np.ndarray:
    """The carrier times eq. 2's modulation, which the renderer applies per sample."""
    carrier = make_source(resolved.pattern.carrier, FS).block(0, resolved.frames)
    factor = modulation_at(resolved, np.arange(resolved.frames) / FS)
    return carrier.astype(np.float64) * (1.0 if factor is None else factor)


def test_per_sample_gains_give_carrier_times_control_gains():
    resolved = plan_of(gain_update_frames=1)
    out = PatternRenderer(resolved).render(resolved.frames)
    t = np.arange(resolved.frames) / FS
    expected = carrier_of(resolved)[:, None] * control_gains(resolved, t, modulated=False)
    np.testing.assert_allclose(out, expected, rtol=0, atol=FLOAT32)


@pytest.mark.parametrize("step", [7, 32, 100])
def test_ramped_gains_interpolate_linearly_between_grid_points(step):
    resolved = plan_of(gain_update_frames=step, gain_ramp=True)
    out = PatternRenderer(resolved).render(resolved.frames)
    n = np.arange(resolved.frames)
    grid_n = np.arange(0, resolved.frames + step, step)
    grid = control_gains(resolved, grid_n / FS, modulated=False)
    gains = np.column_stack([np.interp(n, grid_n, grid[:, k]) for k in range(8)])
    np.testing.assert_allclose(out, carrier_of(resolved)[:, None] * gains, atol=FLOAT32)


@pytest.mark.parametrize("step", [7, 32])
def test_held_gains_step_at_grid_points(step):
    resolved = plan_of(gain_update_frames=step, gain_ramp=False)
    out = PatternRenderer(resolved).render(resolved.frames)
    held = (np.arange(resolved.frames) // step) * step
    gains = control_gains(resolved, held / FS, modulated=False)
    np.testing.assert_allclose(out, carrier_of(resolved)[:, None] * gains, atol=FLOAT32)


def test_gain_block_matches_its_definition(rng):
    step, offset, frames = 16, 5, 200
    carrier = rng.standard_normal(frames).astype(np.float32)
    cells = (offset + frames + step - 1) // step
    grid = rng.uniform(0, 1, size=(cells + 1, 3)).astype(np.float32)
    out = gain_block(carrier, grid, step, offset, ramp=True)
    for i in range(frames):
        j, r = divmod(offset + i, step)
        gain = (1 - r / step) * grid[j].astype(np.float64) + (r / step) * grid[j + 1]
        np.testing.assert_allclose(out[i], carrier[i] * gain, rtol=0, atol=FLOAT32)


@pytest.mark.parametrize("carrier", [{"kind": "sine"}, {"kind": "noise", "seed": 4}])
def test_render_add_adds_what_render_into_writes(rng, carrier):
    resolved = plan_of(carrier)
    written = np.empty((resolved.frames, 8), dtype=np.float32)
    into = PatternRenderer(resolved)
    add = PatternRenderer(resolved)
    base = rng.uniform(-0.1, 0.1, size=(resolved.frames, 8)).astype(np.float32)
    mixed = base.copy()
    for start in range(0, resolved.frames, 333):
        into.render_into(written[start : start + 333])
        add.render_add(mixed[start : start + 333])
    # One float32 addition per sample.
    np.testing.assert_allclose(mixed, base + written, rtol=0, atol=FLOAT32)


def test_frames_past_the_end_are_silent_and_untouched():
    resolved = plan_of()
    voice = PatternRenderer(resolved)
    out = np.full((resolved.frames + 500, 8), 7.0, dtype=np.float32)
    voice.render_into(out)
    assert voice.finished and voice.remaining_frames == 0
    np.testing.assert_array_equal(out[resolved.frames :], 0.0)
    more = np.full((100, 8), 7.0, dtype=np.float32)
    voice.render_add(more)
    np.testing.assert_array_equal(more, 7.0)


@pytest.mark.parametrize("block", [1, 7, 256, 1000, 4096])
def test_the_active_span_holds_every_channel_a_block_drives(block):
    resolved = plan_of()  # an arc over the layout: the driven channels change as it moves
    voice = PatternRenderer(resolved)
    out = np.empty((block, 8), dtype=np.float32)
    spans = set()
    while not voice.finished:
        voice.render_into(out)
        lo, hi = voice.active_span
        assert 0 <= lo < hi <= 8
        assert not np.any(out[:, :lo]) and not np.any(out[:, hi:])
        spans.add((lo, hi))
    assert len(spans) > 1
    voice.render_into(out)  # past the end: silent
    assert voice.active_span == (0, 0) and not np.any(out)
