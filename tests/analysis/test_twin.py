import math

import numpy as np
import pytest
from scipy import signal

from phantomtouch import DeviceProfile, ParameterError
from phantomtouch.analysis.twin import (
    ActuatorModel,
    ArmbandTwin,
    TwinLoop,
    amplitude_m_s2,
    euler_accelerations,
)

RATES_HZ = (8000, 48000, 192000)


def lock_in_amplitude(x: np.ndarray, freq_hz: float, rate_hz: float) -> float:
    """Amplitude of the component of x at freq_hz, over the whole periods at its end."""
    periods = math.floor(len(x) * freq_hz / rate_hz)
    n = round(periods * rate_hz / freq_hz)
    t = np.arange(len(x) - n, len(x)) / rate_hz
    return 2.0 * abs(np.mean(x[-n:] * np.exp(-2j * np.pi * freq_hz * t)))


def test_analog_gain_at_resonance_is_gain_times_q() -> None:
    model = ActuatorModel(f0_hz=170.0, q=3.0, level_db=150.0)
    assert abs(model.response(170.0)) == pytest.approx(model.gain_m_s2 * 3.0, rel=1e-12)
    # the level holds at ref_hz by construction: |H(ref)| is a full-scale sine's peak
    assert abs(model.response(100.0)) == pytest.approx(amplitude_m_s2(150.0), rel=1e-12)


@pytest.mark.parametrize("q", [0.7071, 3.0, 50.0, 1000.0])
@pytest.mark.parametrize("rate_hz", RATES_HZ)
def test_digital_gain_at_resonance_equals_analytic(q: float, rate_hz: int) -> None:
    # the bilinear transform warped at f0 maps the analog w0 exactly onto f0
    model = ActuatorModel(f0_hz=170.0, q=q)
    _, h = signal.sosfreqz(model.sos(rate_hz), worN=[170.0], fs=rate_hz)
    assert abs(h[0]) == pytest.approx(model.gain_m_s2 * q, rel=1e-9)


def test_steady_state_sine_at_resonance_reaches_gain_times_q() -> None:
    rate, model = 48000, ActuatorModel(f0_hz=170.0, q=5.0, level_db=140.0)
    settle_s = 20 * model.q / (math.pi * model.f0_hz)  # 20 time constants of the envelope
    t = np.arange(round((settle_s + 0.2) * rate)) / rate
    out = signal.sosfilt(model.sos(rate), np.sin(2 * np.pi * 170.0 * t))
    # 1e-4: the transient has decayed by e^-20; whole periods are rounded to frames
    steady = out[round(settle_s * rate) :]
    assert lock_in_amplitude(steady, 170.0, rate) == pytest.approx(model.gain_m_s2 * 5.0, rel=1e-4)


def test_euler_agrees_with_bilinear_when_oversampled(rng: np.random.Generator) -> None:
    # far below Nyquist and with low Q both integrate the same equation
    rate, model = 192000, ActuatorModel(f0_hz=100.0, q=0.7)
    t = np.arange(rate) / rate
    drive = np.sin(2 * np.pi * 60.0 * t)
    exact = lock_in_amplitude(signal.sosfilt(model.sos(rate), drive)[rate // 2 :], 60.0, rate)
    naive = euler_accelerations(model, drive, sample_rate_hz=rate)[rate // 2 :]
    naive = lock_in_amplitude(naive, 60.0, rate)
    assert naive == pytest.approx(exact, rel=5e-3)  # first-order method: error ~ f0 / fs


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"f0_hz": 0.0}, "f0_hz"),
        ({"f0_hz": float("nan")}, "f0_hz"),
        ({"q": -1.0}, "q"),
        ({"ref_hz": 0.0}, "ref_hz"),
        ({"level_db": float("inf")}, "level_db"),
    ],
)
def test_invalid_model_names_the_field(kwargs: dict[str, float], field: str) -> None:
    with pytest.raises(ParameterError, match=field):
        ActuatorModel(**kwargs)


def test_resonance_at_or_above_nyquist_is_refused() -> None:
    with pytest.raises(ParameterError, match="f0_hz=24000"):
        ActuatorModel(f0_hz=24000.0).sos(48000)


def test_block_wise_twin_equals_whole(rng: np.random.Generator) -> None:
    device = DeviceProfile.default()
    drive = rng.standard_normal((5000, 8)).astype(np.float32)
    whole = ArmbandTwin(device).process(drive)
    twin = ArmbandTwin(device)
    parts = np.concatenate([twin.process(drive[a:b]) for a, b in ((0, 7), (7, 1000), (1000, 5000))])
    np.testing.assert_allclose(parts, whole, rtol=1e-12, atol=1e-9)


def test_twin_loop_records_the_sensor_actuator_late_and_scaled() -> None:
    device = DeviceProfile.default()
    twin = ArmbandTwin(device)
    loop = TwinLoop(ArmbandTwin(device), input_scale_m_s2=50.0, latency_frames=123)
    loop.place_sensor(3)
    drive = np.zeros((2000, 8), np.float32)
    drive[:, 2] = np.sin(np.arange(2000) * 0.05)
    drive[:, 0] = 1.0  # another actuator: not under the sensor
    recorded = loop(drive)
    expected = twin.process(drive)[:, 2] / 50.0
    np.testing.assert_array_equal(recorded[:123], 0.0)
    np.testing.assert_allclose(recorded[123:], expected[:-123], rtol=1e-12)
    with pytest.raises(ParameterError, match="channel=9"):
        loop.place_sensor(9)
