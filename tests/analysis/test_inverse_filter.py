import numpy as np
import pytest
from scipy import signal

from phantomtouch import DeviceProfile
from phantomtouch.analysis.inverse_filter import (
    BAND_HZ,
    Transfer,
    estimate_transfer,
    fir_gain,
    inverse_fir,
    target_response,
)
from phantomtouch.analysis.twin import ActuatorModel, ArmbandTwin

RATE = 48000
# a soft, a sharp and a high resonance, within ±6 dB of the nominal level
MODELS = [
    ActuatorModel(f0_hz=140.0, q=2.0, level_db=149.0),
    ActuatorModel(f0_hz=150.0, q=5.0, level_db=161.0),
    ActuatorModel(f0_hz=210.0, q=3.0, level_db=156.5),
]


def test_transfer_estimate_recovers_the_analytic_response(rng: np.random.Generator) -> None:
    model = MODELS[1]  # Q = 5: the sharpest resonance
    twin = ArmbandTwin(DeviceProfile.default(), [model] * 8)
    drive = np.zeros((8 * RATE, 8))
    drive[:, 1] = 0.1 * rng.standard_normal(8 * RATE)
    accel = twin.process(drive)[:, 1]
    delayed = np.concatenate([np.zeros(250), accel[:-250]])
    transfer = estimate_transfer(drive[:, 1], delayed, sample_rate_hz=RATE)
    assert transfer.delay_frames == 250
    band = (transfer.freqs_hz >= BAND_HZ[0]) & (transfer.freqs_hz <= BAND_HZ[1])
    expected = np.abs(model.response(transfer.freqs_hz[band]))
    error_db = 20 * np.log10(np.abs(transfer.response[band]) / expected)
    # Welch's Hann window (2.9 Hz resolution) flattens the resonance peak by ~0.25 dB
    assert np.max(np.abs(error_db)) < 0.3


@pytest.mark.parametrize("model", MODELS)
def test_inverse_fir_flattens_the_band_and_boosts_nothing_outside(model: ActuatorModel) -> None:
    freqs = np.linspace(0.0, RATE / 2, 8193)
    transfer = Transfer(freqs, model.response(freqs), np.ones_like(freqs), 0)
    taps = inverse_fir(
        transfer, sample_rate_hz=RATE, taps=4096, reference_hz=100.0, measured_hz=(20.0, 1000.0)
    )
    check = np.array([40.0, 50.0, 75.0, 100.0, 150.0, 250.0, 400.0, 500.0])
    corrected = fir_gain(taps, check, RATE) * np.abs(model.response(check))
    corrected_db = 20 * np.log10(corrected / abs(model.response(100.0)))
    target_db = 20 * np.log10(target_response(check))
    assert corrected_db[3] == pytest.approx(0.0, abs=1e-9)  # gain exactly 1 at 100 Hz
    # the target is flat within 0.26 dB over the band; the FIR meets it within 0.3 dB
    np.testing.assert_allclose(corrected_db, target_db, atol=0.3)
    assert np.all(np.abs(target_db) < 0.26)
    # outside the band nothing is boosted beyond the band's largest correction
    in_band = fir_gain(taps, np.linspace(*BAND_HZ, 200), RATE).max()
    outside = fir_gain(taps, np.array([0.0, 2.0, 5.0, 2000.0, 10000.0, 23000.0]), RATE)
    assert np.all(outside < in_band)
    # minimum phase: no bulk delay, where a linear-phase FIR of 4096 taps adds 42.7 ms
    _, delay = signal.group_delay((taps, [1.0]), w=[50.0, 100.0, 150.0, 300.0], fs=RATE)
    assert np.all(np.abs(delay) / RATE < 0.010)
