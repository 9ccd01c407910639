"""The SQLite pattern library."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from phantomtouch.errors import DeviceError
from phantomtouch.renderer import preset
from phantomtouch.server.store import PatternStore

SUMMARY = {"duration_s": 1.0}


def test_put_get_list_delete(tmp_path: Path) -> None:
    store = PatternStore.open(tmp_path / "sub" / "p.db")
    pattern = preset("vr/stroke")
    assert store.put("b-stroke", pattern, SUMMARY) is True
    assert store.put("a.tap", preset("vr/tap"), SUMMARY) is True
    assert store.put("b-stroke", pattern, {"duration_s": 2.0}) is False
    assert store.get("b-stroke") == pattern
    assert store.list() == [("a.tap", SUMMARY), ("b-stroke", {"duration_s": 2.0})]
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


def test_not_a_database_is_a_device_error(tmp_path: Path) -> None:
    path = tmp_path / "p.db"
    path.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(DeviceError, match="cannot open the pattern store"):
        PatternStore.open(path)
