"""A haptic clip as a pattern's carrier: its envelope, frequency and transients in the render.

The pattern rests on actuator 1 (channel 1 alone, gain 1 with the power law) without
fades, so channel 1 is the pattern's amplitude times the clip's signal.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import hilbert

from phantomtouch import TouchPattern, plan, render, render_blocks
from phantomtouch.clips import load_clip
from phantomtouch.errors import ParameterError
from phantomtouch.renderer.clip import CLIP_HIGH_HZ, CLIP_LOW_HZ, TRANSIENT_CYCLES, clip_freq_hz
from phantomtouch.schema import HapticClip

SAMPLES = Path(__file__).parents[1] / "clips" / "samples"
FS = 48_000


def at_actuator_1(clip: HapticClip, *, duration_s: float, loop: bool = False) -> TouchPattern:
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
            "duration_s": duration_s,
            "fade_in_s": 0.0,
            "fade_out_s": 0.0,
            "intensity": 0.5,
            "carrier": {"kind": "clip", "clip": "c", "loop": loop, "data": clip.model_dump()},
        }
    )


def channel_1(pattern: TouchPattern) -> tuple[np.ndarray, float]:
    out = render(pattern, sample_rate_hz=FS)
    assert np.abs(out[:, 1:]).max() == 0.0  # the touch is on actuator 1 alone
    return out[:, 0].astype(np.float64), plan(pattern).amplitude


def test_the_rms_envelope_follows_the_breakpoints_within_half_a_db() -> None:
    """Windows of 40 ms around each breakpoint of swell.haptic: RMS against the file's own
    envelope, ``A * a(t) / sqrt(2)`` averaged over the window. A window of a sine that
    does not hold whole cycles is off by at most ``1 / (4 pi f T)`` in power, 0.17 dB at
    50 Hz."""
    clip = load_clip(SAMPLES / "swell.haptic")
    signal, amplitude = channel_1(at_actuator_1(clip, duration_s=clip.duration_s))
    window_s = 0.04
    emphasis = [
        (t.t_s, t.t_s + TRANSIENT_CYCLES / clip_freq_hz(t.frequency)) for t in clip.transients
    ]
    checked = 0
    for point in clip.amplitude:
        start_s = min(max(0.0, point.t_s - window_s / 2), clip.duration_s - window_s)
        end_s = start_s + window_s
        if any(start_s < t1 and t0 < end_s for t0, t1 in emphasis):
            continue  # the emphasis adds its click here: see the transient test
        frames = slice(round(start_s * FS), round(end_s * FS))
        times_s = np.arange(frames.start, frames.stop) / FS
        expected = amplitude * np.sqrt(
            np.mean(
                np.interp(
                    times_s, [p.t_s for p in clip.amplitude], [p.value for p in clip.amplitude]
                )
                ** 2
            )
            / 2
        )
        measured = np.sqrt(np.mean(signal[frames] ** 2))
        assert 20 * np.log10(measured / expected) == pytest.approx(0.0, abs=0.5), point
        checked += 1
    assert checked == len(clip.amplitude) - 1  # all but the one under the emphasis


def test_the_frequency_follows_the_band_mapping() -> None:
    """Frequency 0, 0.5 and 1 in steps: zero crossings count 50, 112 and 250 Hz."""
    steps = [(0.0, 0.0), (1.0, 0.0), (1.0, 0.5), (2.0, 0.5), (2.0, 1.0), (3.0, 1.0)]
    clip = HapticClip(
        duration_s=3.0,
        amplitude=[{"t_s": 0.0, "value": 1.0}],  # type: ignore[list-item]
        frequency=[{"t_s": t, "value": v} for t, v in steps],  # type: ignore[misc]
    )
    signal, amplitude = channel_1(at_actuator_1(clip, duration_s=3.0))
    for second, value in enumerate((0.0, 0.5, 1.0)):
        part = signal[second * FS + FS // 10 : (second + 1) * FS - FS // 10]
        crossings = np.flatnonzero(np.diff(np.signbit(part)))  # two per cycle
        measured_hz = (len(crossings) - 1) / 2 / ((crossings[-1] - crossings[0]) / FS)
        expected_hz = CLIP_LOW_HZ * (CLIP_HIGH_HZ / CLIP_LOW_HZ) ** value
        assert measured_hz == pytest.approx(expected_hz, rel=0.01)
    # The phase runs on through each step: no sample jumps further than a full-amplitude
    # sine at 250 Hz moves in one frame.
    assert np.abs(np.diff(signal)).max() <= amplitude * 2 * np.pi * CLIP_HIGH_HZ / FS * 1.001


def test_transients_are_clicks_at_their_times_with_their_strength_and_pitch() -> None:
    clip = load_clip(SAMPLES / "knock.ahap")
    signal, amplitude = channel_1(at_actuator_1(clip, duration_s=clip.duration_s))
    for transient in clip.transients:
        freq_hz = float(clip_freq_hz(transient.frequency))
        length = round(TRANSIENT_CYCLES / freq_hz * FS)
        start = round(transient.t_s * FS)
        burst = signal[start : start + length]
        # A Hann window over three cycles peaks at 0.93 of the amplitude where the sine
        # peaks nearest its middle (1.25 and 1.75 cycles in).
        peak = np.abs(burst).max() / amplitude
        assert transient.amplitude * 0.9 <= peak <= transient.amplitude * 1.0001
        spectrum = np.abs(np.fft.rfft(burst, 1 << 16))
        peak_hz = np.fft.rfftfreq(1 << 16, 1 / FS)[np.argmax(spectrum)]
        assert peak_hz == pytest.approx(freq_hz, rel=0.1)
        # And nothing between the clicks (the continuous event starts at 1.0 s).
        after = signal[start + length + 10 : start + length + 2000]
        assert np.abs(after).max() == 0.0


def test_blocks_concatenate_to_the_whole_render_and_loops_repeat() -> None:
    clip = load_clip(SAMPLES / "knock.ahap")
    pattern = at_actuator_1(clip, duration_s=2 * clip.duration_s + 0.3, loop=True)
    whole = render(pattern, sample_rate_hz=FS)
    blocks = np.concatenate(list(render_blocks(pattern, sample_rate_hz=FS, block_frames=997)))
    np.testing.assert_array_equal(blocks, whole)
    period = round(clip.duration_s * FS)
    once = whole[:period, 0].astype(np.float64)
    again = whole[period : 2 * period, 0].astype(np.float64)

    # The clicks (the first 0.9 s) repeat sample for sample; the continuous part's phase
    # runs on, so its envelope is compared: the magnitude of the analytic signal, which
    # for a sine under a slow envelope is the envelope.
    clicks = round(0.9 * FS)
    np.testing.assert_allclose(again[:clicks], once[:clicks], rtol=0, atol=1e-6)
    # Away from the ends and from the sharpness step at 2.0 s, where the analytic
    # signal's magnitude depends on the phase the step meets.
    t_s = np.arange(period) / FS
    inner = (t_s > 0.95) & (t_s < 2.45) & (np.abs(t_s - 2.0) > 0.03)
    envelope_once = np.abs(hilbert(once))[inner]
    envelope_again = np.abs(hilbert(again))[inner]
    np.testing.assert_allclose(envelope_again, envelope_once, atol=0.01 * envelope_once.max())
    # Without loop the clip plays once: silence after its end.
    single = render(at_actuator_1(clip, duration_s=clip.duration_s + 0.5), sample_rate_hz=FS)
    assert np.abs(single[period + 1 :]).max() == 0.0


def test_a_clip_carrier_without_its_clip_is_refused() -> None:
    pattern = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
            "duration_s": 1.0,
            "carrier": {"kind": "clip", "clip": "not-filled-in"},
        }
    )
    with pytest.raises(ParameterError, match=r"carrier.clip='not-filled-in'"):
        plan(pattern)
