"""The fleet's command-line flags refuse a half-given address before anything starts."""

from __future__ import annotations

from pathlib import Path

import pytest

from phantomtouch.cli import EXIT_USAGE, main


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["serve", "--armband", "a1"], "--armband and --site need --fleet"),
        (["serve", "--fleet-insecure"], "--fleet-insecure needs --fleet"),
        (["serve", "--fleet", "nats://127.0.0.1:4222"], "--fleet needs --armband ID"),
        (["serve", "--fleet", "nats://127.0.0.1:4222", "--armband", "a.1"], "armband"),
        (["serve", "--fleet", "http://127.0.0.1:4222", "--armband", "a1"], "nats://HOST:PORT"),
        (["gateway", "--fleet", "nats://user:pw@127.0.0.1:4222"], "must not carry credentials"),
    ],
)
def test_a_bad_fleet_flag_is_a_usage_error(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    extra = ["--db", str(tmp_path / "patterns.db"), "--output", "null"]
    assert main(argv if argv[0] == "gateway" else [*argv, *extra]) == EXIT_USAGE
    assert message in capsys.readouterr().err
    assert not (tmp_path / "patterns.db").exists()  # refused before anything opened
