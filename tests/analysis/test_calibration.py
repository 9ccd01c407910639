import math

import pytest

from phantomtouch import DeviceError, DeviceProfile, ParameterError
from phantomtouch.analysis.calibration import CalibrationSettings, calibrate
from phantomtouch.analysis.profile_file import write_profile
from phantomtouch.analysis.sound_input import input_scale, sounddevice_loop
from phantomtouch.analysis.twin import ActuatorModel, ArmbandTwin, TwinLoop, amplitude_m_s2

RATE = 48000
# every actuator different, as on a real arm: resonance, Q and level (within ±6 dB)
MODELS = [
    ActuatorModel(f0_hz=f0, q=q, level_db=155.0 + g)
    for f0, q, g in zip(
        [140, 150, 160, 170, 180, 190, 200, 210],
        [2.0, 5.0, 3.0, 4.0, 2.5, 3.5, 4.5, 3.0],
        [-6.0, 6.0, -3.0, 3.0, 0.0, -4.5, 4.5, 1.5],
        strict=True,
    )
]
SCALE_M_S2 = amplitude_m_s2(165.0)  # input full scale: a sine at 165 dB


def twin_loop(device: DeviceProfile, **kwargs: float) -> TwinLoop:
    # 7 ms of sound-card latency and sensor noise 80 dB below the input's full scale
    return TwinLoop(
        ArmbandTwin(device, MODELS),
        input_scale_m_s2=SCALE_M_S2,
        latency_frames=317,
        noise_rms=1e-4,
        seed=7,
        **kwargs,
    )


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    device = DeviceProfile.default()
    loop = twin_loop(device)
    result = calibrate(device, loop, input_scale_m_s2=SCALE_M_S2, before_channel=loop.place_sensor)
    path = tmp_path_factory.mktemp("profiles") / "armband.toml"
    write_profile(result.profile, path)
    return result, path


def test_round_trip_meets_every_level_within_one_db(calibrated) -> None:
    result, _ = calibrated
    assert [c.channel for c in result.checks] == list(range(1, 9))
    for check in result.checks:
        # the paper's rig reached ±3 dB; the twin has no measurement error beyond noise
        assert set(check.sine_errors_db) == {"50", "100", "150"}
        assert check.worst_db <= 1.0, check


def test_measured_channel_levels_match_the_actuators(calibrated) -> None:
    result, _ = calibrated
    for model, measured in zip(MODELS, result.measurements, strict=True):
        # each model's level_db holds at 100 Hz, the calibration's reference frequency
        assert measured.level_db == pytest.approx(model.level_db, abs=0.1)
        # the correlation peak moves by the actuator's own phase lead, a few frames
        assert measured.delay_frames == pytest.approx(317, abs=5)
        assert measured.coherence_min > 0.95


def test_the_written_profile_loads_with_the_calibration(calibrated) -> None:
    result, path = calibrated
    loaded = DeviceProfile.load(path)
    assert loaded == result.profile
    cal = loaded.calibration
    assert cal.reference_level_db == 155.0
    assert cal.fir_taps is not None and all(len(t) == 4096 for t in cal.fir_taps)


def test_only_the_chosen_channels_are_calibrated() -> None:
    device = DeviceProfile.default()
    loop = twin_loop(device)
    loop.place_sensor(2)
    result = calibrate(
        device,
        loop,
        input_scale_m_s2=SCALE_M_S2,
        channels=[2],
        settings=CalibrationSettings(excitation_s=4.0, taps=2048),
        check=False,
    )
    cal = result.profile.calibration
    assert cal.channel_level_db is not None and cal.fir_taps is not None
    assert cal.channel_level_db[1] == pytest.approx(MODELS[1].level_db, abs=0.1)
    assert [cal.channel_level_db[k] for k in (0, 2, 3, 4, 5, 6, 7)] == [155.0] * 7
    assert cal.fir_taps[0] == (1.0,) and len(cal.fir_taps[1]) == 2048


def test_a_sensor_on_the_wrong_actuator_is_reported() -> None:
    device = DeviceProfile.default()
    loop = twin_loop(device)
    loop.place_sensor(5)  # but channel 1 is measured: the input holds only noise
    with pytest.raises(DeviceError, match="channel 1: coherence"):
        calibrate(
            device,
            loop,
            input_scale_m_s2=SCALE_M_S2,
            channels=[1],
            settings=CalibrationSettings(excitation_s=2.0),
        )


def test_input_scale_from_sensitivity_or_reference_level() -> None:
    # 10 mV per m/s² into an input whose full scale is 2 V: 200 m/s² per unit
    assert input_scale(sensitivity_v_per_m_s2=0.01, input_full_scale_v=2.0) == 200.0
    assert input_scale(input_reference_level_db=160.0) == pytest.approx(
        math.sqrt(2) * 1e-6 * 10 ** (160 / 20)
    )
    with pytest.raises(ParameterError, match="sensitivity_v_per_m_s2"):
        input_scale(sensitivity_v_per_m_s2=0.01)
    with pytest.raises(ParameterError, match="input_full_scale_v=-1"):
        input_scale(sensitivity_v_per_m_s2=0.01, input_full_scale_v=-1.0)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"excitation_hz": (60.0, 1000.0)}, "excitation_hz"),
        ({"drive_rms": 0.0}, "drive_rms"),
        ({"taps": 5000}, "taps"),
        ({"reference_hz": 1000.0}, "reference_hz"),
    ],
)
def test_bad_settings_name_the_parameter(kwargs: dict, name: str) -> None:
    with pytest.raises(ParameterError, match=name):
        CalibrationSettings(**kwargs)


def test_unwired_channel_is_refused() -> None:
    with pytest.raises(ParameterError, match="channel=9"):
        calibrate(DeviceProfile.default(), lambda d: d[:, 0], input_scale_m_s2=1.0, channels=[9])


def test_sound_card_loop_refuses_input_channel_zero() -> None:
    pytest.importorskip("sounddevice")
    with pytest.raises(ParameterError, match="input_channel=0"):
        sounddevice_loop(
            sample_rate_hz=RATE, output_device=None, input_device=None, input_channel=0
        )
