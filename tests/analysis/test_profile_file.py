import tomllib

import numpy as np
import pytest

from phantomtouch import DeviceError, DeviceProfile, ParameterError
from phantomtouch.analysis.profile_file import profile_toml, write_profile
from phantomtouch.schema import Actuator, Calibration


def calibrated_profile(rng: np.random.Generator) -> DeviceProfile:
    taps = tuple(tuple(float(v) for v in rng.standard_normal(50) * 1e-7) for _ in range(8))
    calibration = Calibration(channel_level_db=tuple(rng.uniform(140, 160, 8)), fir_taps=taps)
    return DeviceProfile.model_validate(
        {**DeviceProfile.default().model_dump(), "name": 'lab "A" – ü', "calibration": calibration}
    )


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_written_profile_loads_back_equal(suffix: str, tmp_path, rng) -> None:
    profile = calibrated_profile(rng)
    write_profile(profile, tmp_path / f"p{suffix}")
    assert DeviceProfile.load(tmp_path / f"p{suffix}") == profile


def test_custom_layout_round_trips(tmp_path) -> None:
    actuators = [
        Actuator(x_cm=x, y_cm=y, channel=c)
        for c, (x, y) in enumerate([(0, 0), (2, 0), (1, 1.7), (3, 1.7)], start=1)
    ]
    profile = DeviceProfile(actuators=tuple(actuators), name="four", gain_ramp=False)
    write_profile(profile, tmp_path / "four.toml")
    assert DeviceProfile.load(tmp_path / "four.toml") == profile
    assert DeviceProfile.load(tmp_path / "four.toml").triangles is None


def test_toml_puts_tables_after_the_top_level_keys(rng) -> None:
    data = tomllib.loads(profile_toml(calibrated_profile(rng)))
    assert data["sample_rate_hz"] == 48000 and len(data["actuators"]) == 8
    assert len(data["calibration"]["fir_taps"][3]) == 50


def test_unknown_suffix_and_unwritable_path_are_refused(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"must end in \.toml or \.json"):
        write_profile(DeviceProfile.default(), tmp_path / "p.yaml")
    with pytest.raises(DeviceError, match="cannot write"):
        write_profile(DeviceProfile.default(), tmp_path / "missing" / "p.toml")


@pytest.mark.parametrize(
    "name", ["armband 😀", "tab\tnewline\ndel\x7f", "𝄞 clef and é", 'quote " backslash \\']
)
def test_any_name_round_trips_through_toml(name: str, tmp_path) -> None:
    # Characters beyond the BMP, control characters and DEL, which TOML escapes its own way.
    profile = DeviceProfile(name=name)
    write_profile(profile, tmp_path / "p.toml")
    assert DeviceProfile.load(tmp_path / "p.toml").name == name
