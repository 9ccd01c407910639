"""Carriers: sine RMS and phase, band-limited noise spectrum and RMS, the combined signal."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from phantomtouch.renderer.carriers import (
    NOISE_ORDER,
    NOISE_PERIOD_FRAMES,
    CombinedSource,
    NoiseSource,
    SineSource,
    band_pass_gain,
    sine_blocks,
)

FS = 48000
UNIT_SINE_RMS = 1 / np.sqrt(2)


def noise(low_hz=40.0, high_hz=500.0, seed=0, seconds=10.0, block=4800) -> np.ndarray:
    source = NoiseSource(low_hz, high_hz, seed, FS)
    frames = int(seconds * FS)
    return np.concatenate([source.block(n, block) for n in range(0, frames, block)])


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(x, dtype=np.float64) ** 2)))


# --- sine ----------------------------------------------------------------------------------


@pytest.mark.parametrize("freq_hz", [50.0, 100.0, 150.0, 1000.0])
def test_sine_rms_is_one_over_root_two(freq_hz):
    whole_cycles = int(FS / np.gcd(int(freq_hz), FS))  # frames holding whole cycles
    x = SineSource(freq_hz, FS).block(0, whole_cycles * max(1, 4800 // whole_cycles))
    assert x.dtype == np.float32
    # float32 samples carry ~6e-8 relative rounding; the mean of squares averages it out.
    assert rms(x) == pytest.approx(UNIT_SINE_RMS, rel=1e-6)


@pytest.mark.parametrize("freq_hz", [50.0, 100.0, 150.0, 333.3])
def test_sine_phase_derivative_is_its_frequency(freq_hz):
    x = SineSource(freq_hz, FS).block(0, FS).astype(np.float64)
    phase = np.unwrap(np.angle(signal.hilbert(x)))
    # Fit the phase in the middle (the analytic signal is distorted at the ends).
    n = np.arange(len(x))[FS // 10 : -FS // 10]
    slope = np.polyfit(n, phase[n], 1)[0]
    # A least-squares slope over 0.8 s of a clean phase: far better than 1e-6 relative.
    assert slope * FS / (2 * np.pi) == pytest.approx(freq_hz, rel=1e-6)
    # And the FFT of 1 s (1 Hz bins) peaks in the bin of that frequency.
    spectrum = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    assert np.fft.rfftfreq(len(x), 1 / FS)[np.argmax(spectrum)] == pytest.approx(freq_hz, abs=1)


def test_sine_is_a_function_of_the_absolute_frame_only():
    source = SineSource(100.0, FS)
    whole = source.block(0, 10000)
    parts = np.concatenate([source.block(n, 999) for n in range(0, 10000, 999)])[:10000]
    np.testing.assert_array_equal(parts, whole)


def test_sine_keeps_its_phase_after_two_hours():
    # Frame n has phase 2 pi (n f / fs mod 1); with f and fs integers the fraction is exact.
    start = 7200 * FS - 100
    x = SineSource(100.0, FS).block(start, 200)
    n = np.arange(start, start + 200)
    exact = np.sin(2 * np.pi * ((n * 100) % FS) / FS)
    # float32 output: half an ulp of 1 is 6e-8, the float32 phase adds about 4e-7.
    np.testing.assert_allclose(x, exact, rtol=0, atol=1e-6)


# --- band-limited noise ----------------------------------------------------------------------


def test_noise_is_at_least_40_db_down_outside_its_band():
    x = noise(seconds=10.0)
    # No detrending: removing each segment's mean would leak the in-band power into the
    # lowest bins through a rectangular window and measure the estimator, not the noise.
    # 16384-frame segments resolve 2.9 Hz, enough to see 20 Hz apart from 40 Hz.
    freqs, psd = signal.welch(x.astype(np.float64), fs=FS, nperseg=16384, detrend=False)
    in_band = psd[(freqs >= 40) & (freqs <= 500)].mean()
    below = psd[freqs < 20].max()
    above = psd[freqs > 1000].max()
    assert 10 * np.log10(below / in_band) <= -40
    assert 10 * np.log10(above / in_band) <= -40


def test_noise_filter_response_is_40_db_down_an_octave_outside_the_band():
    # The filter itself, analytically: 8 poles per edge give 48 dB per octave.
    level_db = 20 * np.log10(band_pass_gain(40.0, 500.0, FS, np.array([20, 40, 100, 500, 1000])))
    assert level_db[0] <= -40 and level_db[-1] <= -40
    # Butterworth: -3.01 dB at each edge and flat in between (0.05 and 0.1 dB are far
    # below the 3 dB JND of vibration amplitude and only allow for the design's rounding).
    np.testing.assert_allclose(level_db[[1, 3]], -3.0, atol=0.05)
    assert level_db[2] == pytest.approx(0.0, abs=0.1)


@pytest.mark.parametrize("low_hz, high_hz", [(1.0, 20.0), (40.0, 500.0), (5000.0, 20000.0)])
def test_noise_filter_response_is_scipys_digital_butterworth(low_hz, high_hz):
    sos = signal.butter(NOISE_ORDER, [low_hz, high_hz], btype="bandpass", fs=FS, output="sos")
    freqs = np.geomspace(0.1, FS / 2, 2000)
    _, response = signal.sosfreqz(sos, worN=freqs, fs=FS)
    # The closed form and scipy's second-order sections agree to the sections' rounding
    # (1e-7 relative at a 1 Hz edge, far less elsewhere); 1e-12 absolute far down the skirts.
    np.testing.assert_allclose(
        band_pass_gain(low_hz, high_hz, FS, freqs), np.abs(response), rtol=1e-6, atol=1e-12
    )


@pytest.mark.parametrize("seed", [0, 1, 12345])
def test_noise_rms_is_a_unit_sines(seed):
    x = noise(seed=seed, seconds=10.0)
    assert x.dtype == np.float32
    # The mean square of noise of bandwidth B over T seconds varies by about 1/sqrt(B T)
    # = 1.5 % (B = 460 Hz, T = 10 s); its RMS by half that. 4 % is over 5 sigma.
    assert rms(x) == pytest.approx(UNIT_SINE_RMS, rel=0.04)


def test_noise_loops_seamlessly():
    source = NoiseSource(40.0, 500.0, 0, FS)
    loop = source.block(0, NOISE_PERIOD_FRAMES).astype(np.float64)
    # The whole loop has exactly the RMS (to float32 rounding of its samples).
    assert rms(loop) == pytest.approx(UNIT_SINE_RMS, rel=1e-6)
    # The step from the last frame back to the first is no larger than the steps inside.
    assert abs(loop[0] - loop[-1]) <= np.abs(np.diff(loop)).max()
    # 10 s straddling the seam has the spectrum and RMS of any 10 s (see the tests above):
    # a step at the seam, whose spectrum falls as 1/f, would show in the stop band below.
    across = source.block(NOISE_PERIOD_FRAMES - 5 * FS, 10 * FS).astype(np.float64)
    np.testing.assert_array_equal(across[5 * FS :], loop[: 5 * FS])
    freqs, psd = signal.welch(across, fs=FS, nperseg=16384, detrend=False)
    in_band = psd[(freqs >= 40) & (freqs <= 500)].mean()
    assert 10 * np.log10(psd[freqs < 20].max() / in_band) <= -40
    assert 10 * np.log10(psd[freqs > 1000].max() / in_band) <= -40
    assert rms(across) == pytest.approx(UNIT_SINE_RMS, rel=0.04)


def test_noise_is_reproducible_per_seed_and_differs_between_seeds():
    a = noise(seed=7, seconds=2.0)
    np.testing.assert_array_equal(a, noise(seed=7, seconds=2.0, block=1000))
    b = noise(seed=8, seconds=2.0)
    assert not np.array_equal(a, b)
    # Independent seeds: noise of bandwidth B over T seconds has about 2 B T = 1840
    # independent samples, so the correlation spreads by 1/sqrt(1840) = 0.023; 0.12 is
    # over 5 sigma.
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.12


def test_noise_is_a_function_of_the_absolute_frame_only():
    source = NoiseSource(40.0, 500.0, 0, FS)
    whole = source.block(0, 3 * FS)
    starts = [2 * FS, 0, 17, FS + 999]  # out of order, overlapping
    for start in starts:
        np.testing.assert_array_equal(source.block(start, 4096), whole[start : start + 4096])
    later = source.block(5 * NOISE_PERIOD_FRAMES + 100, 4096)
    np.testing.assert_array_equal(later, whole[100 : 100 + 4096])
    # Blocks are copies: a caller may scale them in place.
    block = source.block(0, 100)
    block *= 0.0
    np.testing.assert_array_equal(source.block(0, 100), whole[:100])


# --- combined ---------------------------------------------------------------------------------


@pytest.mark.parametrize("freq_hz", [50.0, 100.0, 150.0])
def test_combined_rms_equals_the_sines(freq_hz):
    frames = 10 * FS
    combined = CombinedSource(SineSource(freq_hz, FS), NoiseSource(40.0, 500.0, 3, FS))
    x = combined.block(0, frames)
    sine = SineSource(freq_hz, FS).block(0, frames)
    # The paper's recipe: noise with the sine's RMS added to it, the sum scaled back to
    # the sine's RMS (two uncorrelated equal parts: divide by sqrt(2)). Same seed, same
    # noise; float32 rounding of the sum stays below 1e-6.
    parts = (sine.astype(np.float64) + noise(seed=3, seconds=10.0, block=frames)) / np.sqrt(2)
    np.testing.assert_allclose(x, parts, rtol=0, atol=1e-6)
    # Measured: the noise power over 10 s spreads by ~0.4 % and the sine-noise cross term
    # (the noise's own component at freq_hz) by ~1.5 % of the mean square, so the RMS
    # spreads by ~0.8 %; 4 % is about 5 sigma.
    assert rms(x) == pytest.approx(rms(sine), rel=0.04)
    assert rms(sine) == pytest.approx(UNIT_SINE_RMS, rel=1e-6)


def test_many_sines_at_once_are_each_sines_own_block_bit_for_bit() -> None:
    """The engine computes its contacts' sine carriers together; each row is what the
    sine's own source gives, however far into the carrier (hours of frames) it is."""
    rate = 48_000
    freqs_hz = [20.0, 100.0, 150.0, 333.3, 1000.0]
    starts = [0, 17, 4_800_123, 172_800_000, 999]
    frames = 128
    rows = sine_blocks(
        np.array(starts, dtype=np.float64),
        np.array([f / rate for f in freqs_hz]),
        np.arange(frames, dtype=np.float64),
    )
    for row, freq_hz, start in zip(rows, freqs_hz, starts, strict=True):
        np.testing.assert_array_equal(row, SineSource(freq_hz, rate).block(start, frames))


def test_many_sines_into_given_buffers_are_the_same_bits_and_fill_them() -> None:
    """With ``out`` and ``scratch`` (the callback's buffers) the blocks are those of a new
    array, bit for bit, written into ``out``."""
    rate = 48_000
    starts = np.array([0, 4_800_123, 172_800_000], dtype=np.float64)
    cycles = np.array([f / rate for f in (20.0, 250.0, 1000.0)])
    index = np.arange(64, dtype=np.float64)
    out = np.full((3, 64), np.nan, dtype=np.float32)
    scratch = (np.empty((3, 64)), np.empty((3, 64)))
    given = sine_blocks(starts, cycles, index, out=out, scratch=scratch)
    assert given is out
    assert out.tobytes() == sine_blocks(starts, cycles, index).tobytes()
