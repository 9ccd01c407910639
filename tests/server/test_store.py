"""The SQLite pattern library."""

from __future__ import annotations

import json
import logging
import sqlite3
from pathlib import Path
from typing import Any

import pytest

from phantomtouch.errors import DeviceError
from phantomtouch.renderer import plan_at, preset
from phantomtouch.service.errors import StoredPatternError
from phantomtouch.service.store import DamagedStoreError, PatternStore

SUMMARY: dict[str, Any] = plan_at(preset("vr/tap")).summary()
LONGER = {**SUMMARY, "duration_s": 2.0}


def test_put_get_list_delete(tmp_path: Path) -> None:
    store = PatternStore.open(tmp_path / "sub" / "p.db")
    pattern = preset("vr/stroke")
    assert store.put("b-stroke", pattern, SUMMARY) is True
    assert store.put("a.tap", preset("vr/tap"), SUMMARY) is True
    assert store.put("b-stroke", pattern, LONGER) is False
    assert store.get("b-stroke") == pattern
    assert store.list() == [("a.tap", SUMMARY), ("b-stroke", LONGER)]
    assert store.delete("a.tap") is True
    assert store.delete("a.tap") is False
    assert store.get("a.tap") is None
    store.close()


def test_wal_journal_and_reopen(tmp_path: Path) -> None:
    path = tmp_path / "p.db"
    store = PatternStore.open(path)
    store.put("x", preset("vr/tap"), SUMMARY)
    store.close()
    mode = sqlite3.connect(path).execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"
    again = PatternStore.open(path)
    assert again.get("x") == preset("vr/tap")
    again.close()


def test_not_a_database_is_damaged_and_says_what_to_do(tmp_path: Path) -> None:
    path = tmp_path / "my library" / "p.db"
    path.parent.mkdir()
    path.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(DamagedStoreError) as damaged:
        PatternStore.open(path)
    message = str(damaged.value)
    assert str(path) in message and "file is not a database" in message
    assert f"mv '{path}' '{path}.damaged'" in message, "quoted for the shell"
    assert isinstance(damaged.value, DeviceError)


def test_unwritable_folder_is_a_device_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("a file where the folder should be")
    with pytest.raises(DeviceError, match="cannot open the pattern store"):
        PatternStore.open(blocker / "p.db")


@pytest.mark.parametrize(
    ("pattern", "summary"),
    [
        ("not json", None),
        (json.dumps({"path": {"kind": "polyline", "points_cm": [[1, 1]]}, "speed_cm_s": -1}), None),
        (None, "{}"),
    ],
)
def test_unreadable_row_is_the_library_fault_and_the_rest_stays_usable(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, pattern: str | None, summary: str | None
) -> None:
    path = tmp_path / "p.db"
    store = PatternStore.open(path)
    store.put("good", preset("vr/tap"), SUMMARY)
    store.put("bad", preset("vr/tap"), SUMMARY)
    with sqlite3.connect(path) as db:
        if pattern is not None:
            db.execute("UPDATE patterns SET pattern = ? WHERE name = 'bad'", (pattern,))
        if summary is not None:
            db.execute("UPDATE patterns SET summary = ? WHERE name = 'bad'", (summary,))
    with caplog.at_level(logging.WARNING, logger="phantomtouch.server.store"):
        assert store.list() == [("good", SUMMARY)]
    assert "pattern='bad': the stored row no longer reads" in caplog.text
    assert store.get("good") == preset("vr/tap")
    if pattern is not None:
        with pytest.raises(StoredPatternError, match="PUT it again or DELETE it") as refused:
            store.get("bad")
        assert refused.value.status_code == 500
    assert store.delete("bad") is True
    store.close()


def test_clip_sizes_are_kept_and_read_once_for_a_clip_stored_before(tmp_path: Path) -> None:
    """A library written before the sizes were kept (no ``clip_sizes`` rows) lists the
    same sizes, read from the clips' JSON, and a replaced clip never shows its old ones."""
    from phantomtouch.schema import HapticClip
    from phantomtouch.service.store import ClipSize

    path = tmp_path / "p.db"
    store = PatternStore.open(path)
    clip = HapticClip.model_validate(
        {"duration_s": 2.0, "amplitude": [{"t_s": 0.0, "value": 1.0}, {"t_s": 1.0, "value": 0.0}]}
    )
    store.put_clip("a", clip)
    store.put_clip("b", clip)
    store.put_clip("b", clip.model_copy(update={"duration_s": 3.0}))
    expected = [ClipSize("a", 2.0, 2, 1, 0), ClipSize("b", 3.0, 2, 1, 0)]
    assert store.clip_sizes(limit=10) == expected
    store.close()
    with sqlite3.connect(path) as db:
        db.execute("DELETE FROM clip_sizes")
    again = PatternStore.open(path)
    assert again.clip_sizes(limit=10) == expected
    assert again.clip_sizes(limit=1, offset=1) == expected[1:]
    again.close()
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT COUNT(*) FROM clip_sizes").fetchone() == (2,)
