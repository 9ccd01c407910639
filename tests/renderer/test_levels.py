"""Intensity: the paper's Table I levels, and the level a rendered signal really has."""

from __future__ import annotations

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.errors import ParameterError
from phantomtouch.renderer.levels import TABLE_I_DB, table_i_level_db
from phantomtouch.schema import DeviceProfile, SineCarrier, TouchPattern

REFERENCE_DB = 155.0  # calibration.reference_level_db: a full-scale sine
FS = 48000

# Kirchner et al. 2023, Table I, dB re 1 um/s^2: (signal, low, high).
PAPER_TABLE_I = [
    ({"kind": "sine", "freq_hz": 50}, 128, 138),
    ({"kind": "sine", "freq_hz": 100}, 128, 138),
    ({"kind": "sine", "freq_hz": 150}, 131, 141),
    ({"kind": "combined", "freq_hz": 50}, 128, 138),
    ({"kind": "combined", "freq_hz": 100}, 128, 138),
    ({"kind": "combined", "freq_hz": 150}, 131, 141),
    ({"kind": "noise"}, 135, 145),
]


def still_touch(carrier: dict, **fields) -> TouchPattern:
    """A point on actuator 1 (channel 1) for 1 s at full level, with 0.1 s fades."""
    data = {
        "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
        "duration_s": 1.2,
        "fade_in_s": 0.1,
        "fade_out_s": 0.1,
        "carrier": carrier,
    }
    data.update(fields)
    return TouchPattern.model_validate(data)


def level_db(x: np.ndarray) -> float:
    """Level of a signal: a sine of amplitude a (RMS a / sqrt 2) is 155 + 20 log10 a."""
    rms = np.sqrt(np.mean(np.asarray(x, dtype=np.float64) ** 2))
    return REFERENCE_DB + 20 * np.log10(rms * np.sqrt(2))


def test_table_i_is_the_papers():
    assert TABLE_I_DB == {
        "low": {"50": 128.0, "100": 128.0, "150": 131.0, "noise": 135.0},
        "high": {"50": 138.0, "100": 138.0, "150": 141.0, "noise": 145.0},
    }


@pytest.mark.parametrize("carrier, low_db, high_db", PAPER_TABLE_I)
def test_intensity_presets_give_the_table_i_level(carrier, low_db, high_db):
    for intensity, expected in (("low", low_db), ("high", high_db)):
        resolved = pt.plan(still_touch(carrier, intensity=intensity))
        assert resolved.level_db == expected
        # Amplitude 1.0 is a full-scale sine at 155 dB.
        assert resolved.amplitude == pytest.approx(10 ** ((expected - REFERENCE_DB) / 20))


@pytest.mark.parametrize("freq_hz, intensity", [(50, "low"), (100, "high"), (150, "low")])
def test_rendered_sine_has_the_level_it_asked_for(freq_hz, intensity):
    touch = still_touch({"kind": "sine", "freq_hz": freq_hz}, intensity=intensity)
    resolved = pt.plan(touch)
    out = pt.render(touch)
    # 1 s of full level (after the fade-in) holds whole cycles of 50, 100 and 150 Hz.
    steady = out[int(0.1 * FS) : int(1.1 * FS), 0]
    # float32 samples: the level is exact to far better than 0.001 dB.
    assert level_db(steady) == pytest.approx(resolved.level_db, abs=1e-3)


@pytest.mark.parametrize("carrier", [{"kind": "noise"}, {"kind": "combined", "freq_hz": 100}])
def test_rendered_noise_and_combined_have_their_level(carrier):
    touch = still_touch(carrier, intensity="low", duration_s=5.2)
    resolved = pt.plan(touch)
    steady = pt.render(touch)[int(0.1 * FS) : int(5.1 * FS), 0]
    # 5 s of 460 Hz wide noise: the mean square spreads by 1/sqrt(B T) = 2 %, 0.09 dB;
    # 0.5 dB is over 5 sigma (and far below the 3 dB JND of vibration amplitude).
    assert level_db(steady) == pytest.approx(resolved.level_db, abs=0.5)


def test_relative_intensity_is_relative_to_the_devices_maximum_level():
    device = DeviceProfile.default()
    full = pt.plan(still_touch({"kind": "sine"}, intensity=1.0))
    assert full.level_db == device.safety.max_level_db == 150.0
    half = pt.plan(still_touch({"kind": "sine"}, intensity=0.5))
    assert half.level_db == pytest.approx(150.0 + 20 * np.log10(0.5))
    assert half.amplitude == pytest.approx(full.amplitude / 2)


def test_zero_intensity_is_silence():
    touch = still_touch({"kind": "sine"}, intensity=0.0)
    resolved = pt.plan(touch)
    assert resolved.level_db is None
    assert resolved.amplitude == 0.0
    np.testing.assert_array_equal(pt.render(touch), 0.0)


def test_level_db_replaces_intensity():
    resolved = pt.plan(still_touch({"kind": "sine"}, level_db=120.0))
    assert resolved.level_db == 120.0
    assert resolved.amplitude == pytest.approx(10 ** ((120 - 155) / 20))


def test_level_above_the_devices_maximum_is_refused():
    with pytest.raises(ParameterError) as info:
        pt.plan(still_touch({"kind": "sine"}, level_db=151.0))
    assert "level_db: it gives 151 dB" in str(info.value)
    assert "safety.max_level_db=150" in str(info.value)
    quiet = DeviceProfile(safety={"max_level_db": 130.0})
    with pytest.raises(
        ParameterError, match=r"intensity: it gives 138 dB .*safety\.max_level_db=130"
    ):
        pt.plan(still_touch({"kind": "sine"}, intensity="high"), quiet)


def test_table_i_between_and_beyond_its_columns():
    # Interpolated in log frequency between 100 Hz (128) and 150 Hz (131): their
    # geometric mean lies half way. Outside 50-150 Hz the nearest column holds.
    assert table_i_level_db("low", SineCarrier(freq_hz=np.sqrt(100 * 150))) == pytest.approx(129.5)
    assert table_i_level_db("low", SineCarrier(freq_hz=20.0)) == 128.0
    assert table_i_level_db("high", SineCarrier(freq_hz=400.0)) == 141.0
