"""The stimulus manifest: the factors of each stimulus as columns, floats without noise."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

import phantomtouch as pt
from phantomtouch.manifest import COLUMNS, SIGNIFICANT_DIGITS, factors, row, write_manifest

EXP1 = [name for name in pt.preset_names() if name.startswith("exp1/")]


def exp1_rows() -> list[dict[str, object]]:
    return [row(name, f"{name}.wav", pt.preset(name), pt.plan(pt.preset(name))) for name in EXP1]


def test_exp1_factors_are_the_papers_design() -> None:
    rows = exp1_rows()
    assert len(rows) == 84
    # Experiment 1 crosses carrier/frequency, intensity, speed and AM: every stimulus is
    # told apart by its factor columns alone, without its file name.
    keys = {(r["carrier"], r["freq_hz"], r["intensity"], r["speed_cm_s"], r["am"]) for r in rows}
    assert len(keys) == 84
    assert {r["speed_cm_s"] for r in rows} == {3.0, 10.0, 18.0}
    assert {r["intensity"] for r in rows} == {"low", "high"}
    assert {r["am"] for r in rows} == {True, False}
    assert {r["carrier"] for r in rows} == {"sine", "noise", "combined"}
    assert all(r["freq_hz"] is None for r in rows if r["carrier"] == "noise")
    assert all(r["am_index"] == 0.0 and r["am_freq_hz"] is None for r in rows if not r["am"])


def test_durations_follow_eq_1_without_float_noise() -> None:
    for r in exp1_rows():
        # eq. 1 per stroke, two strokes: 2 (0.6 + 14.4 / v + 0.6) s.
        expected_s = 2 * (0.6 + 14.4 / float(r["speed_cm_s"]) + 0.6)  # type: ignore[arg-type]
        assert r["duration_s"] == pytest.approx(expected_s, rel=1e-9)
        for value in r.values():
            if isinstance(value, float):
                assert len(repr(value).replace(".", "").lstrip("0-")) <= SIGNIFICANT_DIGITS + 4
    slow = next(r for r in exp1_rows() if r["speed_cm_s"] == 3.0)
    assert slow["duration_s"] == 12.0, "12.0, not 11.999999999999998"


def test_level_db_replaces_intensity() -> None:
    pattern = pt.TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 2], [1.9, 12]]},
            "speed_cm_s": 5,
            "level_db": 120,
        }
    )
    f = factors(pattern, pt.plan(pattern))
    assert f["intensity"] is None
    assert f["level_db"] == 120.0


def test_json_and_csv_hold_the_same_rows(tmp_path: Path) -> None:
    rows = exp1_rows()[:6]
    json_path, csv_path = write_manifest(rows, tmp_path)
    by_name = json.loads(json_path.read_text(encoding="utf-8"))
    with csv_path.open(newline="", encoding="utf-8") as handle:
        table = list(csv.DictReader(handle))
    assert list(table[0]) == list(COLUMNS)
    assert [r["name"] for r in table] == [r["name"] for r in rows] == list(by_name)
    for r, line in zip(rows, table, strict=True):
        assert by_name[r["name"]]["speed_cm_s"] == r["speed_cm_s"]
        assert float(line["duration_s"]) == r["duration_s"]
        assert line["freq_hz"] == ("" if r["freq_hz"] is None else str(r["freq_hz"]))
