"""The real ``phantomtouch`` console script, run in a temporary folder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile

import phantomtouch as pt
from phantomtouch.schema import TouchPattern

SCRIPT = Path(sys.executable).parent / "phantomtouch"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(SCRIPT), *args], cwd=cwd, capture_output=True, text=True, timeout=120, check=False
    )


def read_wav(path: Path) -> np.ndarray:
    samples, rate = soundfile.read(str(path), dtype="float32", always_2d=True)
    info = soundfile.info(str(path))
    assert info.subtype == "FLOAT"
    assert rate == 48000
    return samples


def test_render_preset_writes_wav_plot_and_plan(tmp_path):
    result = run(
        "render",
        "--preset",
        "exp2/curved",
        "-o",
        "x.wav",
        "--plot",
        "x.png",
        "--json",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    for key in ("duration_s", "path_length_cm", "speed_cm_s", "frames", "channels"):
        assert key in summary
    assert summary["channels"] == 8
    assert summary["duration_s"] == pytest.approx(2.9)
    samples = read_wav(tmp_path / "x.wav")
    assert samples.shape == (summary["frames"], 8)
    # A float32 WAV holds the render exactly.
    np.testing.assert_array_equal(samples, pt.render(pt.preset("exp2/curved")))
    assert (tmp_path / "x.png").read_bytes()[:8] == PNG_SIGNATURE


def test_render_pattern_file(tmp_path):
    pattern = {
        "path": {
            "kind": "arc",
            "start_cm": [3.8, 12.0],
            "through_cm": [0.0, 7.2],
            "end_cm": [3.8, 2.4],
        },
        "speed_cm_s": 7.0,
        "carrier": {"kind": "combined", "freq_hz": 150, "seed": 5},
        "intensity": "low",
        "modulation": {"index": 1.0, "freq_hz": "stroke"},
    }
    (tmp_path / "touch.json").write_text(json.dumps(pattern), encoding="utf-8")
    result = run("render", "touch.json", "-o", "touch.wav", "--json", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["speed_cm_s"] == 7.0
    assert summary["clipped_fraction"] == 0.0
    expected = pt.render(TouchPattern.model_validate(pattern))
    np.testing.assert_array_equal(read_wav(tmp_path / "touch.wav"), expected)


def test_render_reports_the_frames_the_ceiling_clipped(tmp_path):
    pattern = {
        "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
        "duration_s": 2.0,
        "carrier": {"kind": "noise"},
        "level_db": 150.0,
    }
    (tmp_path / "loud.json").write_text(json.dumps(pattern), encoding="utf-8")
    result = run("render", "loud.json", "-o", "loud.wav", "--json", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    samples = read_wav(tmp_path / "loud.wav")
    at_ceiling = float(np.mean((np.abs(samples) >= np.float32(1.0)).any(axis=1)))
    assert at_ceiling > 0.0
    assert json.loads(result.stdout)["clipped_fraction"] == at_ceiling
    text = run("render", "loud.json", "-o", "loud.wav", cwd=tmp_path)
    assert "reach the safety ceiling 1 and are clipped" in text.stdout


def test_presets_lists_every_preset(tmp_path):
    result = run("presets", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    names = [line.split()[0] for line in result.stdout.splitlines() if line.strip()]
    assert len([n for n in names if n.startswith("exp1/")]) == 84
    assert len([n for n in names if n.startswith("exp2/")]) == 4
    assert len(names) >= 84 + 4
    assert names == pt.preset_names()


def test_stimuli_exp2_writes_four_wavs_and_a_manifest(tmp_path):
    result = run("stimuli", "exp2", "-o", "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    out = tmp_path / "out"
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert sorted(manifest) == ["exp2/central", "exp2/curved", "exp2/diagonal", "exp2/right"]
    assert sorted(p.name for p in out.glob("*.wav")) == [
        "central.wav",
        "curved.wav",
        "diagonal.wav",
        "right.wav",
    ]
    for name, entry in manifest.items():
        samples = read_wav(out / entry["file"])
        assert samples.shape == (entry["frames"], 8)
        assert entry["speed_cm_s"] == pytest.approx(pt.plan(pt.preset(name)).speed_cm_s)


def assert_refused(
    result: subprocess.CompletedProcess[str], *fragments: str, status: int = 2
) -> None:
    # 2: bad input (a field, an argument, a file the user named); 1: a failure while running
    assert result.returncode == status
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("phantomtouch: ")
    for fragment in fragments:
        assert fragment in lines[0]


def test_invalid_field_in_a_pattern_file_is_refused_in_one_line(tmp_path):
    bad = {"path": {"kind": "polyline", "points_cm": [[1, 1], [1, 5]]}, "speed_cm_s": 0}
    (tmp_path / "bad.json").write_text(json.dumps(bad), encoding="utf-8")
    result = run("render", "bad.json", "-o", "x.wav", cwd=tmp_path)
    assert_refused(result, "speed_cm_s=0", "greater than 0")
    assert not (tmp_path / "x.wav").exists()


def test_malformed_json_is_refused_in_one_line(tmp_path):
    (tmp_path / "bad.json").write_text('{"path": ', encoding="utf-8")
    result = run("render", "bad.json", "-o", "x.wav", cwd=tmp_path)
    assert_refused(result, "pattern file 'bad.json'", "Invalid JSON")


def test_unknown_preset_is_refused_in_one_line(tmp_path):
    result = run("render", "--preset", "exp2/curvd", "-o", "x.wav", cwd=tmp_path)
    assert_refused(result, "preset='exp2/curvd'", "exp2/curved")


def test_missing_pattern_file_is_refused_in_one_line(tmp_path):
    result = run("render", "missing.json", "-o", "x.wav", cwd=tmp_path)
    assert_refused(result, "missing.json", "No such file")


def test_frequency_above_nyquist_at_a_lower_rate_is_refused_in_one_line(tmp_path):
    touch = {
        "path": {"kind": "polyline", "points_cm": [[1, 1]]},
        "duration_s": 1.0,
        "carrier": {"kind": "sine", "freq_hz": 5000},
    }
    (tmp_path / "t.json").write_text(json.dumps(touch), encoding="utf-8")
    result = run("render", "t.json", "-o", "x.wav", "--sample-rate", "8000", cwd=tmp_path)
    assert_refused(result, "carrier.freq_hz=5000.0", "Nyquist frequency 4000 Hz")


def test_degenerate_device_file_is_refused_in_one_line(tmp_path):
    lines = []
    for i, y in enumerate([0.0, 1.0, 2.0]):
        lines += ["[[actuators]]", "x_cm = 0.0", f"y_cm = {y}", f"channel = {i + 1}"]
    (tmp_path / "line.toml").write_text("\n".join(lines) + "\n", encoding="utf-8")
    result = run(
        "render", "--preset", "vr/tap", "-o", "x.wav", "--device", "line.toml", cwd=tmp_path
    )
    assert_refused(result, "line.toml", "collinear")


def test_unwritable_output_is_refused_in_one_line(tmp_path):
    result = run("render", "--preset", "vr/tap", "-o", "no/such/dir/x.wav", cwd=tmp_path)
    assert_refused(result, "no/such/dir/x.wav", "folder 'no/such/dir' does not exist")


def test_version(tmp_path):
    result = run("--version", cwd=tmp_path)
    assert result.returncode == 0
    assert result.stdout.strip() == f"phantomtouch {pt.__version__}"


def test_serve_without_the_audio_extra_says_it_plays_to_the_null_output(tmp_path):
    code = (
        "import sys, importlib.abc\n"
        "class Hide(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] == 'sounddevice':\n"
        "            raise ModuleNotFoundError(name)\n"
        "sys.meta_path.insert(0, Hide())\n"
        "from phantomtouch.cli import main\n"
        "sys.exit(main(['serve', '--port', '70000']))\n"  # refused after the warning
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2  # the bad port, after the warning
    assert "sounddevice is not installed" in result.stderr
    assert "playing to the null output" in result.stderr


def test_serve_without_the_server_extra_names_the_extra(tmp_path):
    # The core alone: fastapi made unimportable, as in an install without [server].
    code = (
        "import sys, importlib.abc\n"
        "class Hide(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] == 'fastapi':\n"
        "            raise ModuleNotFoundError(name)\n"
        "sys.meta_path.insert(0, Hide())\n"
        "from phantomtouch.cli import main\n"
        "sys.exit(main(['serve', '--port', '8799']))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert "scripts/install installs it (or .venv/bin/pip install -e '.[server]')" in result.stderr
