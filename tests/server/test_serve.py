"""``phantomtouch serve``: settings from flags and environment, refused before binding."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from phantomtouch.cli import main
from phantomtouch.service.listen import log_config
from tests.support.live_server import free_port


def test_public_bind_without_token_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--host", "0.0.0.0", "--port", "8765"]) == 2
    assert "requires a token" in capsys.readouterr().err


def test_bad_port_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--port", "70000"]) == 2
    assert "port=70000" in capsys.readouterr().err


def test_start_up_lines_are_logged() -> None:
    assert log_config()["loggers"]["phantomtouch"]["level"] == "INFO"


def test_ctrl_c_fades_out_and_exits_without_a_traceback(tmp_path: Path) -> None:
    """Ctrl+C reaches the whole process group, the engine process included."""
    port = free_port()
    log = tmp_path / "serve.log"
    command = [sys.executable, "-m", "phantomtouch", "serve", "--port", str(port)]
    command += ["--output", "null", "--db", str(tmp_path / "p.db")]
    with log.open("wb") as out:
        server = subprocess.Popen(
            command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
    try:
        deadline = time.monotonic() + 60
        while True:
            assert server.poll() is None and time.monotonic() < deadline, log.read_text()
            with contextlib.suppress(httpx.TransportError):
                if httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).status_code == 200:
                    break
            time.sleep(0.1)
        touch = {"preset": "exp2/curved"}
        assert httpx.post(f"http://127.0.0.1:{port}/touch", json=touch).status_code == 202
        os.killpg(server.pid, signal.SIGINT)
        assert server.wait(30) == 0
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(server.pid, signal.SIGKILL)
    output = log.read_text()
    assert "Traceback" not in output and "KeyboardInterrupt" not in output, output
    assert "Application shutdown complete" in output


def test_damaged_library_is_one_line_and_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "patterns.db"
    db.write_bytes(bytes(range(256)) * 32)
    assert main(["serve", "--port", "8765", "--db", str(db), "--output", "null"]) == 1
    captured = capsys.readouterr()
    assert captured.out == "", "nothing starts"
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert str(db) in lines[0] and "move it aside" in lines[0]
