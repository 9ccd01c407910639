"""Whole and block-wise rendering: analytic properties of the samples, and of any input."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError
from scipy import signal

import phantomtouch as pt
from phantomtouch.errors import ParameterError
from phantomtouch.schema import DeviceProfile, TouchPattern
from tests.strategies import PATH_KINDS, layouts, patterns

FS = 48000
DEVICE = DeviceProfile.default()
EXACT_DEVICE = DEVICE.model_copy(update={"gain_update_frames": 1})  # per-sample gains


def touch(**fields) -> TouchPattern:
    return TouchPattern.model_validate(fields)


def still_on_actuator(channel: int, freq_hz: float = 100.0, **fields) -> TouchPattern:
    """1 s at full level on one actuator, framed by 0.1 s fades."""
    x, y = DEVICE.positions_cm()[channel]
    return touch(
        path={"kind": "polyline", "points_cm": [[x, y]]},
        duration_s=1.2,
        fade_in_s=0.1,
        fade_out_s=0.1,
        carrier={"kind": "sine", "freq_hz": freq_hz},
        **fields,
    )


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(x, dtype=np.float64) ** 2)))


# --- a still touch: sine RMS and phase ---------------------------------------------------


@pytest.mark.parametrize("channel", [0, 5])
@pytest.mark.parametrize("freq_hz", [50.0, 100.0, 150.0])
def test_still_sine_has_rms_a_over_root_two_on_its_actuator_alone(channel, freq_hz):
    pattern = still_on_actuator(channel, freq_hz, intensity="high")
    amplitude = pt.plan(pattern).amplitude
    out = pt.render(pattern)
    # the fades excluded, and 20 ms after and before them, where the gain ramps round the
    # envelope's corners (one gain update); 0.96 s holds whole cycles of all carriers
    steady = out[int(0.12 * FS) : int(1.08 * FS)]
    # float32 samples: the RMS is exact to about 1e-7 relative.
    assert rms(steady[:, channel]) == pytest.approx(amplitude / np.sqrt(2), rel=1e-6)
    np.testing.assert_array_equal(np.delete(out, channel, axis=1), 0.0)


@pytest.mark.parametrize("freq_hz", [50.0, 100.0, 150.0, 440.0])
def test_still_sine_phase_derivative_is_its_frequency(freq_hz):
    out = pt.render(still_on_actuator(2, freq_hz))[:, 2].astype(np.float64)
    steady = out[int(0.1 * FS) : int(1.1 * FS)]
    phase = np.unwrap(np.angle(signal.hilbert(steady)))
    n = np.arange(len(steady))[FS // 10 : -FS // 10]  # away from the analytic signal's ends
    slope = np.polyfit(n, phase[n], 1)[0]
    # A least-squares fit over 0.8 s of a clean phase: far better than 1e-6 relative.
    assert slope * FS / (2 * np.pi) == pytest.approx(freq_hz, rel=1e-6)
    # Zero crossings: two per cycle; the window's ends may cut one off or add one each.
    crossings = np.count_nonzero(np.diff(np.signbit(steady[1:-1])))
    assert crossings == pytest.approx(2 * freq_hz, abs=2)


# --- eq. 2 on the rendered samples -------------------------------------------------------


@pytest.mark.parametrize("m", [1.0, 0.5])
def test_modulated_stroke_rms_is_zero_at_its_start_and_full_in_its_middle(m):
    # A moving 2D stroke with the power law: the channels' summed energy is that of one
    # sine with the stroke's envelope, wherever the point is. Per-sample gains.
    pattern = touch(
        path={"kind": "polyline", "points_cm": [[0.5, 13.0], [3.3, 1.0]]},
        speed_cm_s=6.0,
        carrier={"kind": "sine", "freq_hz": 100.0},
        intensity="high",
        modulation={"index": m, "freq_hz": "stroke"},
        repeat=2,
        alternate=True,
    )
    resolved = pt.plan(pattern, EXACT_DEVICE)
    assert resolved.stroke_s == pytest.approx(0.6 + np.hypot(2.8, 12.0) / 6.0 + 0.6)  # 3.25 s
    out = pt.render(pattern, EXACT_DEVICE).astype(np.float64)
    mono_energy = np.sum(out**2, axis=1)  # sum of squared channels, per frame
    t = np.arange(resolved.frames) / FS
    tau = t % resolved.stroke_s
    fades = np.minimum(np.minimum(tau / 0.6, 1.0), (resolved.stroke_s - tau) / 0.6)
    envelope = fades * ((1 - m / 2) - (m / 2) * np.cos(2 * np.pi * tau / resolved.stroke_s))
    expected = (resolved.amplitude * envelope * np.sin(2 * np.pi * 100.0 * t)) ** 2
    # float32 samples squared: ~2e-7 of the full-level energy per frame.
    np.testing.assert_allclose(mono_energy, expected, rtol=0, atol=1e-6 * resolved.amplitude**2)
    cycles = 3 * FS // 100  # three carrier cycles
    for stroke in range(2):
        start = int(stroke * resolved.stroke_s * FS)
        middle = int((stroke + 0.5) * resolved.stroke_s * FS)
        around = slice(middle - cycles // 2, middle + cycles // 2)
        # In the middle eq. 2 is 1 and flat: 15 ms either side of the middle of a 3.25 s
        # stroke it dips by at most (m/2)(2 pi 0.015 / 3.25)^2 / 2 = 2e-4.
        assert np.sqrt(np.mean(mono_energy[around])) == pytest.approx(
            resolved.amplitude / np.sqrt(2), rel=1e-3
        )
        # At the start both the fade and (for m = 1) eq. 2 are 0: 30 ms in, the fade is
        # 0.05 and eq. 2 at most (1 - m) + m (2 pi 0.03 / 3.25)^2 / 4 = (1 - m) + 8e-4.
        first = np.sqrt(np.mean(mono_energy[start : start + cycles]))
        assert first <= resolved.amplitude * 0.05 * ((1 - m) + 1e-3)


# --- block-wise == whole -------------------------------------------------------------------

CARRIERS = [
    {"kind": "sine", "freq_hz": 150.0},
    {"kind": "noise", "seed": 11},
    {"kind": "combined", "freq_hz": 50.0, "seed": 3},
]
GAIN_SETTINGS = [
    {"gain_update_frames": 32, "gain_ramp": True},
    {"gain_update_frames": 1, "gain_ramp": True},
    {"gain_update_frames": 7, "gain_ramp": False},
]
SHORT_STROKE = {
    # Crosses several triangles, with AM, in 0.08 s (3840 frames): short enough for
    # one-frame blocks.
    "path": {"kind": "polyline", "points_cm": [[0.2, 14.0], [3.6, 7.0], [0.5, 0.3]]},
    "duration_s": 0.08,
    "fade_in_s": 0.01,
    "fade_out_s": 0.02,
    "modulation": {"index": 0.7, "freq_hz": 40.0},
    "intensity": 1.0,
}


@pytest.mark.parametrize(
    "gains", GAIN_SETTINGS, ids=lambda g: "{gain_update_frames}-{gain_ramp}".format(**g)
)
@pytest.mark.parametrize("carrier", CARRIERS, ids=lambda c: c["kind"])
def test_blockwise_render_equals_whole_render_bit_for_bit(carrier, gains):
    device = DEVICE.model_copy(update=gains)
    pattern = touch(**SHORT_STROKE, carrier=carrier)
    whole = pt.render(pattern, device)
    assert whole.shape == (pt.plan(pattern, device).frames, 8)
    for block_frames in (1, 7, 256, 1000, 4096):
        blocks = list(pt.render_blocks(pattern, device, block_frames=block_frames))
        assert all(len(b) == block_frames for b in blocks[:-1])
        np.testing.assert_array_equal(np.concatenate(blocks), whole)


def test_render_blocks_memory_is_bounded_by_the_block_size():
    pattern = pt.preset("exp1/combined100-high-v3-am")  # 12 s: 18 MB of output
    resolved = pt.plan(pattern)
    output_bytes = resolved.frames * resolved.channels * 4
    next(pt.render_blocks(pattern))  # designs (and caches) the noise filter first
    tracemalloc.start()
    try:
        blocks = 0
        for _ in pt.render_blocks(pattern, block_frames=1024):
            blocks += 1
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert blocks == -(-resolved.frames // 1024)
    # A 1024-frame block is 32 kB; with the plan, the noise generator and temporaries
    # about 0.25 MB, whatever the pattern's length. 1/20 of the output is 0.9 MB: memory
    # that grew with the pattern would show far above it.
    assert peak < output_bytes / 20


def test_block_frames_below_one_is_refused():
    with pytest.raises(ParameterError, match="block_frames=0 must be >= 1"):
        next(pt.render_blocks(pt.preset("exp2/right"), block_frames=0))


# --- output format and the safety ceiling -------------------------------------------------


def test_render_at_another_sample_rate():
    pattern = pt.preset("exp2/central")
    out = pt.render(pattern, sample_rate_hz=44100)
    assert out.shape == (round(2.9 * 44100), 8)
    assert out.dtype == np.float32


def test_loud_noise_never_exceeds_the_ceiling():
    # Gaussian noise at 150 dB (amplitude 0.56, RMS 0.4) peaks far above full scale.
    pattern = touch(
        path={"kind": "polyline", "points_cm": [[0.0, 0.0], [0.0, 4.8]]},
        speed_cm_s=4.8,
        carrier={"kind": "noise", "seed": 1},
        intensity=1.0,
        fade_in_s=0.0,
        fade_out_s=0.0,
    )
    for ceiling in (1.0, 0.25):
        device = DEVICE.model_copy(
            update={"safety": DEVICE.safety.model_copy(update={"ceiling": ceiling})}
        )
        out = pt.render(pattern, device)
        assert np.max(np.abs(out)) == np.float32(ceiling)  # reached, and not exceeded


def check_output(pattern: TouchPattern, device: DeviceProfile) -> None:
    """Render, or refuse with a message that names what is wrong."""
    try:
        resolved = pt.plan(pattern, device)
    except ParameterError as exc:
        # Legitimate refusals of a random pattern: an arc through collinear points, a
        # speed past the maximum, a still keyframe without fades.
        message = str(exc)
        assert any(name in message for name in ("path", "duration_s", "zero duration")), message
        return
    out = pt.render(pattern, device)
    assert out.shape == (resolved.frames, device.channels)
    assert out.dtype == np.float32
    assert np.all(np.isfinite(out))
    assert np.max(np.abs(out), initial=0.0) <= device.safety.ceiling


@pytest.mark.parametrize("kind", PATH_KINDS)
@settings(max_examples=15)
@given(data=st.data())
def test_random_patterns_render_finite_within_the_ceiling(kind, data):
    pattern = data.draw(patterns(kinds=(kind,)))
    check_output(TouchPattern.model_validate(pattern), DEVICE)


@settings(max_examples=25)
@given(data=patterns(), device=layouts(), ceiling=st.floats(0.05, 1.0))
def test_random_patterns_on_random_layouts_render_finite_within_the_ceiling(data, device, ceiling):
    device = device.model_copy(
        update={"safety": device.safety.model_copy(update={"ceiling": ceiling})}
    )
    try:
        pattern = TouchPattern.model_validate(data)
    except ValidationError as exc:  # pragma: no cover - the strategy makes valid patterns
        raise AssertionError(exc) from exc
    check_output(pattern, device)
