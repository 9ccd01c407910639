"""The command line's own errors, one line each with exit status 2: an unknown command
(with the nearest one suggested), an output that cannot be written (the reason named),
a malformed pattern file (the file named); and each service command names itself.

Each test runs the real ``phantomtouch`` console script.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.live_server import free_port, free_ports

SCRIPT = Path(sys.executable).parent / "phantomtouch"


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(SCRIPT), *args], cwd=cwd, capture_output=True, text=True, timeout=120, check=False
    )


def one_line(result: subprocess.CompletedProcess[str]) -> str:
    """The only line on stderr of a run refused with status 2, nothing on stdout."""
    assert result.returncode == 2, result.stderr
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in lines[0] and "usage:" not in lines[0]
    return lines[0]


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (
            ("serv",),
            "phantomtouch: no command 'serv'; did you mean 'serve'? "
            "(phantomtouch --help lists the commands)",
        ),
        (("rendr", "x.json"), "phantomtouch: no command 'rendr'; did you mean 'render'?"),
        (
            ("bench", "accurcy"),
            "phantomtouch bench: no command 'accurcy'; did you mean 'accuracy'?",
        ),
        (("zzzz",), "phantomtouch: no command 'zzzz' (phantomtouch --help lists the commands)"),
        (("stimuli", "exp3", "-o", "out"), "'exp3' (choose from 'exp1', 'exp2', 'vr')"),
        (("render",), "phantomtouch render: the following arguments are required: -o/--output"),
        (("presets", "--bogus"), "unrecognized arguments: --bogus"),
    ],
)
def test_a_wrong_argument_is_one_line(tmp_path: Path, args: tuple[str, ...], line: str) -> None:
    assert line in one_line(run(*args, cwd=tmp_path))


def test_an_output_in_a_missing_folder_is_refused_before_rendering(tmp_path: Path) -> None:
    line = one_line(run("render", "--preset", "vr/tap", "-o", "/no/such/dir/x.wav", cwd=tmp_path))
    assert line == (
        "phantomtouch: --output '/no/such/dir/x.wav': the folder '/no/such/dir' does not exist"
    )


def test_an_output_that_is_a_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "out.wav").mkdir()
    line = one_line(run("render", "--preset", "vr/tap", "-o", "out.wav", cwd=tmp_path))
    assert line == "phantomtouch: --output 'out.wav' is a folder; give a file name in it"


def test_a_stimuli_folder_that_cannot_be_made_is_refused(tmp_path: Path) -> None:
    (tmp_path / "taken").write_text("a file where the folder would go\n")
    line = one_line(run("stimuli", "exp2", "-o", "taken/stimuli", cwd=tmp_path))
    assert line.startswith("phantomtouch: --output 'taken/stimuli': cannot make the folder (")
    assert not (tmp_path / "taken").is_dir()


def test_a_clip_output_in_a_missing_folder_is_refused(tmp_path: Path) -> None:
    clip = {"Version": 1.0, "Pattern": [{"Event": {"Time": 0.0, "EventType": "HapticTransient"}}]}
    (tmp_path / "tap.ahap").write_text(json.dumps(clip))
    line = one_line(run("import", "tap.ahap", "-o", "none/tap.json", cwd=tmp_path))
    assert "--output 'none/tap.json': the folder 'none' does not exist" in line


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ('{"path": ', "Invalid JSON"),
        ('{"path": {"kind": "polyline", "points_cm": [[1, 1]]}, "speed_cm_s": -1}', "speed_cm_s"),
    ],
)
def test_a_malformed_pattern_file_is_named(tmp_path: Path, text: str, words: str) -> None:
    (tmp_path / "mine.json").write_text(text)
    line = one_line(run("render", "mine.json", "-o", "mine.wav", cwd=tmp_path))
    assert line.startswith("phantomtouch: pattern file 'mine.json': ")
    assert words in line
    assert not (tmp_path / "mine.wav").exists()


@pytest.mark.parametrize("command", ["serve", "osc"])
def test_each_service_command_names_itself_and_its_library(tmp_path: Path, command: str) -> None:
    db = tmp_path / "lib.db"
    args = [command, "--port", str(free_port()), "--output", "null", "--db", str(db)]
    if command == "osc":
        args += ["--listen", f"127.0.0.1:{free_ports(1)[0]}"]
    service = subprocess.Popen(
        [str(SCRIPT), *args],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        assert service.stdout is not None
        first = service.stdout.readline()
    finally:
        service.send_signal(signal.SIGINT if sys.platform != "win32" else signal.SIGTERM)
        service.wait(timeout=60)
    assert first.startswith(f"phantomtouch {command}: http://127.0.0.1:"), first
    assert f"library {db} (--db FILE for another)" in first
