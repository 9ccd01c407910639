"""What the command line says and writes beyond the WAV: plot file names, projected
points, the size of a stimulus set, its manifest, and a port that is already in use."""

from __future__ import annotations

import csv
import errno
import json
import re
import socket
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from phantomtouch import cli
from tests.test_cli import SCRIPT, assert_refused, run


def test_a_plot_name_that_is_not_an_image_is_refused_before_rendering(tmp_path: Path) -> None:
    result = run("render", "--preset", "vr/tap", "-o", "x.wav", "--plot", "t.txt", cwd=tmp_path)
    assert_refused(result, "--plot 't.txt'", ".png")
    assert not (tmp_path / "x.wav").exists(), "nothing is rendered before the refusal"


def test_a_plot_in_a_missing_folder_is_refused_before_rendering(tmp_path: Path) -> None:
    result = run("render", "--preset", "vr/tap", "-o", "x.wav", "--plot", "no/t.png", cwd=tmp_path)
    assert_refused(result, "no/t.png", "missing")
    assert not (tmp_path / "x.wav").exists()


def test_projected_points_are_reported_without_json(tmp_path: Path) -> None:
    # The first point lies 15.6 cm beyond the elbow end (y = 14.4 cm) of the layout.
    pattern = {"path": {"kind": "polyline", "points_cm": [[1.9, 30], [1.9, 2]]}, "speed_cm_s": 10}
    (tmp_path / "off.json").write_text(json.dumps(pattern), encoding="utf-8")
    result = run("render", "off.json", "-o", "off.wav", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "1 path point(s)" in result.stderr
    assert "up to 15.60 cm" in result.stderr
    inside = run("render", "--preset", "vr/tap", "-o", "tap.wav", cwd=tmp_path)
    assert "projected" not in inside.stderr


def test_stimuli_announce_their_size_and_write_factor_columns(tmp_path: Path) -> None:
    result = run("stimuli", "exp2", "-o", "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    announced = re.search(r"rendering 4 stimuli, (\d+) MB of WAV files", result.stderr)
    assert announced, result.stderr
    written = sum(p.stat().st_size for p in (tmp_path / "out").glob("*.wav"))
    assert int(announced.group(1)) == pytest.approx(written / 1e6, abs=1)
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text(encoding="utf-8"))
    with (tmp_path / "out" / "manifest.csv").open(newline="", encoding="utf-8") as handle:
        table = {r["name"]: r for r in csv.DictReader(handle)}
    assert sorted(table) == sorted(manifest)
    # Experiment 2: the four 2D strokes, each a 100 Hz sine at the low intensity.
    for name, entry in manifest.items():
        assert (entry["carrier"], entry["freq_hz"], entry["intensity"]) == ("sine", 100.0, "low")
        assert table[name]["carrier"] == "sine" and table[name]["file"] == entry["file"]
    assert {e["path"] for e in manifest.values()} >= {"arc", "polyline"}


def test_stimuli_refuse_a_folder_without_room(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def tiny_disk(path: object) -> SimpleNamespace:
        return SimpleNamespace(total=10**9, used=10**9 - 10**6, free=10**6)

    monkeypatch.setattr(cli.shutil, "disk_usage", tiny_disk)
    assert cli.main(["stimuli", "exp2", "-o", str(tmp_path / "out")]) == cli.EXIT_USAGE
    message = capsys.readouterr().err
    assert "only 1 MB are free" in message
    assert list((tmp_path / "out").glob("*.wav")) == []


def test_a_port_in_use_is_refused_before_the_banner(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = str(taken.getsockname()[1])
        result = subprocess.run(
            [str(SCRIPT), "serve", "--port", port, "--output", "null", "--db", "p.db"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    assert result.stdout == "", "no 'serving' banner for a server that cannot start"
    assert_refused(result, f"port={port}", "in use", status=1)  # a failure while running


@pytest.mark.parametrize(
    ("example", "args"),
    [("live_stroke.py", []), ("trial_block.py", ["--presets", "vr/tap"])],
)
def test_client_examples_against_a_dead_server_say_so_in_one_line(
    example: str, args: list[str], tmp_path: Path
) -> None:
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{free.getsockname()[1]}"
    script = Path(__file__).parents[1] / "sdk_clients" / "python" / "examples" / example
    result = subprocess.run(
        [sys.executable, str(script), "--url", dead, *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().count("\n") == 0, result.stderr
    assert f"[Errno {errno.ECONNREFUSED}]" in result.stderr, "says why"
