"""``phantomtouch serve``: settings from flags and environment, refused before binding."""

from __future__ import annotations

from pathlib import Path

import pytest

from phantomtouch.cli import main
from phantomtouch.server.serve import log_config


def test_public_bind_without_token_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--host", "0.0.0.0", "--port", "8765"]) == 2
    assert "requires a token" in capsys.readouterr().err


def test_bad_port_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--port", "70000"]) == 2
    assert "port=70000" in capsys.readouterr().err


def test_start_up_lines_are_logged() -> None:
    assert log_config()["loggers"]["phantomtouch"]["level"] == "INFO"


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
