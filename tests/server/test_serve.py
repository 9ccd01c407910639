"""``phantomtouch serve``: settings from flags and environment, refused before binding."""

from __future__ import annotations

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
