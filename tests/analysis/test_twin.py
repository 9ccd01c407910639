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
QS = (0.1, 0.5, 0.7071, 2.0, 5.0, 50.0, 1000.0)


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


@pytest.mark.parametrize("rate_hz", RATES_HZ)
def test_bilinear_poles_inside_unit_circle_for_every_parameter(rate_hz: int) -> None:
    for f0 in (1.0, 50.0, 170.0, 0.25 * rate_hz, 0.45 * rate_hz, 0.499 * rate_hz):
        for q in QS:
            poles = ActuatorModel(f0_hz=f0, q=q).poles_z(rate_hz)
            assert np.max(np.abs(poles)) < 1.0, (f0, q)


@pytest.mark.parametrize(("f0_fraction", "q"), [(0.49, 3.0), (0.49, 1000.0), (170 / 48000, 1000.0)])
def test_bilinear_output_bounded_where_euler_explodes(
    f0_fraction: float, q: float, rng: np.random.Generator
) -> None:
    rate = 48000
    model = ActuatorModel(f0_hz=f0_fraction * rate, q=q)
    drive = rng.standard_normal(rate)
    stable = signal.sosfilt(model.sos(rate), drive)
    # Parseval: output RMS <= max |H| x input RMS (white noise; 5 % for the finite length)
    _, h = signal.sosfreqz(model.sos(rate), worN=1 << 16, fs=rate)
    assert np.all(np.isfinite(stable))
    assert np.sqrt(np.mean(stable**2)) <= 1.05 * np.max(np.abs(h)) * np.sqrt(np.mean(drive**2))
    # explicit Euler: poles 1 + s/fs outside the unit circle, the output grows without bound
    assert np.max(np.abs(model.euler_poles_z(rate))) > 1.0
    with np.errstate(all="ignore"):
        naive = euler_accelerations(model, drive, sample_rate_hz=rate)
        tail = naive[-rate // 10 :]
        growth = np.sqrt(np.mean(tail**2)) / np.sqrt(np.mean(naive[: rate // 10] ** 2))
    assert not np.all(np.isfinite(tail)) or growth > 1e3


@pytest.mark.parametrize("rate_hz", RATES_HZ)
def test_euler_pole_radius_matches_analytic_condition(rate_hz: int) -> None:
    # |1 + T s|^2 = 1 - T w0 / Q + (T w0)^2 for complex poles: unstable iff T w0 Q > 1
    for f0 in (50.0, 170.0, 0.1 * rate_hz):
        for q in (0.6, 2.0, 5.0, 50.0, 1000.0):
            tw = 2 * math.pi * f0 / rate_hz
            radius = np.max(np.abs(ActuatorModel(f0_hz=f0, q=q).euler_poles_z(rate_hz)))
            assert radius == pytest.approx(math.sqrt(1 - tw / q + tw * tw), rel=1e-9)
            assert (radius > 1.0) == (tw * q > 1.0)


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
