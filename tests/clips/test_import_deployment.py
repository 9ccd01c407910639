"""``phantomtouch import DEPLOYMENT.json``: a game's SDK2 deployment into the library.

The deployments are built in the Developer Portal's shape from the corpus's real ``.tact``
files (``tests/support/deployments.py``); the library is an SQLite file on disk, read back
by the same reader the SDK2 stand-in uses.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from phantomtouch.cli import main
from phantomtouch.service.store import PatternStore
from phantomtouch.service.workspace_library import stored_deployment
from tests.support.deployments import BOTH, RECOIL, effects_end_ms, mapping, portal


def stored_events(db: Path, workspace: str) -> dict[str, int] | None:
    store = PatternStore.open(db)
    try:
        deployment = stored_deployment(store, workspace)
    finally:
        store.close()
    return None if deployment is None else deployment.event_times()


def test_a_default_config_is_stored_under_its_workspace(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "library.db"
    path = tmp_path / "default-config.json"
    path.write_text(json.dumps(BOTH, indent=2), encoding="utf-8")
    assert main(["import", str(path), "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert "imported workspace 'ws-123'" in out and "3 events, 3 of them on an arm" in out
    assert stored_events(db, "ws-123") == {
        "recoil": math.ceil(effects_end_ms(RECOIL)),
        "climb": 274,
        "hit": 100,
    }
    assert main(["import", str(path), "--db", str(db), "--workspace", "other"]) == 0
    assert "imported workspace 'other'" in capsys.readouterr().out
    assert main(["import", str(path), "--db", str(db)]) == 0
    assert "replaced workspace 'ws-123'" in capsys.readouterr().out


def test_a_config_holding_the_json_as_a_string_is_read_once_more(tmp_path: Path) -> None:
    db = tmp_path / "library.db"
    path = tmp_path / "config.json"
    path.write_text(json.dumps(json.dumps(BOTH)), encoding="utf-8")
    assert main(["import", str(path), "--db", str(db)]) == 0
    assert stored_events(db, "ws-123") is not None


def test_output_writes_the_put_body(tmp_path: Path) -> None:
    path = tmp_path / "deployment.json"
    path.write_text(json.dumps(BOTH), encoding="utf-8")
    out = tmp_path / "body.json"
    assert main(["import", str(path), "-o", str(out)]) == 0
    assert json.loads(out.read_text(encoding="utf-8")) == BOTH


def test_a_refusal_is_one_line_naming_the_field_and_stores_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "library.db"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(portal(mapping("a"), mapping("b", eventTime=-5))), "utf-8")
    assert main(["import", str(path), "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "bad.json: message.hapticMappings[1].eventTime=-5 must be an integer" in err
    anonymous = tmp_path / "anonymous.json"
    anonymous.write_text(json.dumps([mapping("a")]), "utf-8")
    assert main(["import", str(anonymous), "--db", str(db)]) == 2
    assert "names no workspaceId; give --workspace" in capsys.readouterr().err
    assert main(["import", str(anonymous), "--db", str(db), "--workspace", "a b"]) == 2
    assert "--workspace='a b' must be" in capsys.readouterr().err
    assert stored_events(db, "ws-123") is None
    not_json = tmp_path / "broken.json"
    not_json.write_text("{nope", "utf-8")
    assert main(["import", str(not_json), "--db", str(db), "--workspace", "w"]) == 2
    assert "broken.json: the deployment is not JSON" in capsys.readouterr().err
