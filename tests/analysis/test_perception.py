import math

import numpy as np
import pytest

from phantomtouch import DeviceProfile, ParameterError, gains_at
from phantomtouch.analysis.perception import perceive, windowed_mean

RATE = 48000


def sine(freq_hz: float, seconds: float, amplitude: float = 1.0) -> np.ndarray:
    return amplitude * np.sin(2 * np.pi * freq_hz * np.arange(round(seconds * RATE)) / RATE)


@pytest.mark.parametrize("channel", range(1, 9))
def test_single_actuator_is_felt_at_its_position_with_its_level(channel: int) -> None:
    device = DeviceProfile.default()
    accel = np.zeros((RATE // 2, 8))
    accel[:, channel - 1] = sine(100.0, 0.5, amplitude=3.0)  # m/s²
    percept = perceive(accel, device)
    actuator = next(a for a in device.actuators if a.channel == channel)
    expected = np.broadcast_to([actuator.x_cm, actuator.y_cm], percept.positions_cm.shape)
    np.testing.assert_allclose(percept.positions_cm, expected)
    # RMS of a sine is A / sqrt(2); the 40 ms window holds 4 whole periods of 100 Hz
    expected_db = 20 * math.log10(3.0 / math.sqrt(2) / 1e-6)
    np.testing.assert_allclose(percept.level_db, expected_db, atol=1e-9)


def test_two_actuators_put_the_centroid_at_the_energy_split() -> None:
    device = DeviceProfile.default()  # channel 1 at (0, 0), channel 2 at (0, 4.8)
    accel = np.zeros((RATE // 4, 8))
    for beta in (0.0, 0.25, 0.5, 0.9):
        accel[:, 0] = sine(150.0, 0.25, math.sqrt(1 - beta))
        accel[:, 1] = sine(150.0, 0.25, math.sqrt(beta))
        percept = perceive(accel, device)
        np.testing.assert_allclose(percept.positions_cm[:, 1], 4.8 * beta, atol=1e-12)
        np.testing.assert_allclose(percept.positions_cm[:, 0], 0.0, atol=1e-12)


def test_power_law_gains_are_felt_exactly_at_the_point(rng: np.random.Generator) -> None:
    # with the power law the energies are the barycentric weights: centroid == point
    device = DeviceProfile.default()
    carrier = sine(100.0, 0.05)
    for x, y in rng.uniform([0.0, 0.0], [3.8, 14.4], size=(20, 2)):
        accel = carrier[:, None] * gains_at(device, x, y)[None, :]
        percept = perceive(accel, device)
        expected = np.broadcast_to([x, y], percept.positions_cm.shape)
        np.testing.assert_allclose(percept.positions_cm, expected, atol=1e-12)


def test_silent_windows_have_no_position_and_no_level() -> None:
    device = DeviceProfile.default()
    accel = np.zeros((RATE // 10, 8))
    accel[RATE // 20 :, 4] = sine(100.0, 0.05)
    percept = perceive(accel, device)
    silent = percept.times_s < 0.05 - 0.04 / 2
    assert np.all(np.isnan(percept.positions_cm[silent]))
    assert np.all(percept.level_db[silent] == -np.inf)
    assert np.all(np.isfinite(percept.level_db[~silent]))


def test_windowed_mean_equals_a_naive_moving_average(rng: np.random.Generator) -> None:
    values = rng.standard_normal((1000, 3))
    window, hop = 60, 20
    expected = [values[s : s + window].mean(axis=0) for s in range(0, 1000 - window + 1, hop)]
    np.testing.assert_allclose(windowed_mean(values, window, hop), expected, rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"window_s": 0.0}, "window_s"), ({"hop_s": 1e-9}, "hop_s"), ({"hop_s": 0.1}, "window_s")],
)
def test_bad_windows_name_the_parameter(kwargs: dict[str, float], name: str) -> None:
    with pytest.raises(ParameterError, match=name):
        perceive(np.zeros((RATE, 8)), DeviceProfile.default(), **kwargs)


def test_too_few_channels_are_refused() -> None:
    with pytest.raises(ParameterError, match="accelerations"):
        perceive(np.zeros((RATE, 4)), DeviceProfile.default())
