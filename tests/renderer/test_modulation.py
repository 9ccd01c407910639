"""Amplitude modulation (eq. 2) in the rendered samples: its spectrum, at any rate."""

from __future__ import annotations

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.schema import DeviceProfile, TouchPattern

DEVICE = DeviceProfile.default()
CARRIER_HZ = 150.0
"""A paper carrier whose sidebands at 150 +- f_m never fall on the carrier for the
modulation frequencies below (the lower one folds to |150 - f_m|)."""
DURATION_S = 2.0
"""Every line below lies on a whole number of 0.5 Hz bins: a rectangular window is exact."""


def modulated_touch(freq_hz: float, index: float) -> TouchPattern:
    x, y = DEVICE.positions_cm()[0]
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[x, y]]},
            "duration_s": DURATION_S,
            "fade_in_s": 0.0,
            "fade_out_s": 0.0,
            "carrier": {"kind": "sine", "freq_hz": CARRIER_HZ},
            "intensity": "low",
            "modulation": {"index": index, "freq_hz": freq_hz},
        }
    )


def line_amplitudes(signal: np.ndarray, sample_rate_hz: int) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and peak amplitudes of the one-sided spectrum (rectangular window)."""
    spectrum = np.abs(np.fft.rfft(np.asarray(signal, dtype=np.float64))) * 2.0 / len(signal)
    return np.fft.rfftfreq(len(signal), 1.0 / sample_rate_hz), spectrum


@pytest.mark.parametrize("sample_rate_hz", [8000, 48000, 192000])
@pytest.mark.parametrize("mod_hz", [50.0, 200.0, 375.0, 750.0, 1000.0])
def test_am_has_the_carrier_and_two_sidebands_of_eq2(mod_hz, sample_rate_hz):
    # sin(2 pi fc t) * ((1 - m/2) - (m/2) cos(2 pi fm t)): the carrier at amplitude
    # (1 - m/2) and one sideband at fc +- fm each at m/4, nothing else.
    index = 1.0
    samples = pt.render(modulated_touch(mod_hz, index), DEVICE, sample_rate_hz=sample_rate_hz)
    channel = samples[:, 0]
    assert np.all(samples[:, 1:] == 0.0)  # a touch on actuator 1 drives it alone
    freqs, amp = line_amplitudes(channel, sample_rate_hz)
    bin_of = {f: int(np.argmin(np.abs(freqs - f))) for f in (CARRIER_HZ, CARRIER_HZ + mod_hz)}
    bin_of[abs(CARRIER_HZ - mod_hz)] = int(np.argmin(np.abs(freqs - abs(CARRIER_HZ - mod_hz))))
    carrier = amp[bin_of[CARRIER_HZ]]
    for f in (CARRIER_HZ + mod_hz, abs(CARRIER_HZ - mod_hz)):
        ratio_db = 20 * np.log10(amp[bin_of[f]] / carrier)
        expected_db = 20 * np.log10((index / 4) / (1 - index / 2))  # -6.02 dB
        assert ratio_db == pytest.approx(expected_db, abs=0.5), f
    # The carrier's own amplitude: (1 - m/2) of the unmodulated sine's peak.
    plain = pt.render(modulated_touch(mod_hz, 0.0), DEVICE, sample_rate_hz=sample_rate_hz)[:, 0]
    unmodulated_peak = line_amplitudes(plain, sample_rate_hz)[1][bin_of[CARRIER_HZ]]
    assert 20 * np.log10(carrier / unmodulated_peak) == pytest.approx(
        20 * np.log10(1 - index / 2), abs=0.5
    )
    # Everything else (aliases of a modulation sampled too slowly) is 40 dB down.
    others = np.ones(len(amp), dtype=bool)
    others[list(bin_of.values())] = False
    assert amp[others].max() < carrier * 10 ** (-40 / 20)


@pytest.mark.parametrize("mod_hz", [375.0, 750.0])
def test_am_at_a_multiple_of_the_gain_grid_rate_is_not_silence(mod_hz):
    # 375 Hz is the rate of a 128-frame gain grid at 48 kHz; modulation sampled on it
    # sits at its minimum (0 for m = 1) at every grid point.
    samples = pt.render(modulated_touch(mod_hz, 1.0), DEVICE, sample_rate_hz=48000)
    rms = float(np.sqrt(np.mean(samples[:, 0].astype(np.float64) ** 2)))
    unmodulated = float(
        np.sqrt(np.mean(pt.render(modulated_touch(mod_hz, 0.0))[:, 0].astype(np.float64) ** 2))
    )
    # E[((1 - cos)/2)^2] = 3/8 of the unmodulated power.
    assert rms / unmodulated == pytest.approx(np.sqrt(3 / 8), rel=0.01)


@pytest.mark.parametrize("block_frames", [1, 100, 128, 1000])
def test_am_block_wise_equals_whole(block_frames):
    pattern = modulated_touch(750.0, 0.8)
    whole = pt.render(pattern)
    blocks = np.concatenate(list(pt.render_blocks(pattern, block_frames=block_frames)))
    np.testing.assert_array_equal(blocks, whole)  # each sample a function of its frame
