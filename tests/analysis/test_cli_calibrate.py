import json

from phantomtouch import DeviceProfile
from phantomtouch.cli import main


def test_simulated_calibration_writes_a_verified_profile(tmp_path, capsys) -> None:
    out = tmp_path / "armband.json"
    argv = ["calibrate", "--simulate", "--channels", "3", "6", "--excitation-s", "4"]
    assert main([*argv, "-o", str(out), "--json", "--seed", "5"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert [c["channel"] for c in report["checks"]] == [3, 6]
    # progress on stderr, one line per channel and pass
    assert captured.err.splitlines() == [
        "calibrate: measuring channel 3 (1 of 2)",
        "calibrate: measuring channel 6 (2 of 2)",
        "calibrate: verifying channel 3 (1 of 2)",
        "calibrate: verifying channel 6 (2 of 2)",
    ]
    assert all(c["worst_db"] <= 1.0 for c in report["checks"])
    profile = DeviceProfile.load(out)
    levels = profile.calibration.channel_level_db
    assert levels is not None
    assert levels[2] == report["measurements"][0]["level_db"]
    assert levels[0] == profile.calibration.reference_level_db  # not measured: nominal


def test_simulated_calibration_prints_a_table(tmp_path, capsys) -> None:
    out = tmp_path / "armband.toml"
    argv = ["calibrate", "--simulate", "--channels", "1", "--excitation-s", "3", "--taps", "2048"]
    assert main([*argv, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "50 Hz" in text and "band err" in text and str(out) in text
    assert DeviceProfile.load(out).calibration.fir_taps is not None


def test_calibrate_needs_the_accelerometer_scale(tmp_path, capsys) -> None:
    assert main(["calibrate", "-o", str(tmp_path / "p.toml"), "--yes"]) == 2
    assert "sensitivity_v_per_m_s2" in capsys.readouterr().err
