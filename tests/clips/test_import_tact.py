"""``phantomtouch import FILE.tact``: real Designer files into the library, or refused.

Every file of the real corpus (``samples/tact/bhaptics-popone-support``, MIT) is imported
into one on-disk library: the 44 with arm content are stored under their names with the
length their own effects give (the latest ``startTime + offsetTime`` of an enabled track,
read here from the raw JSON), the others are refused in one line, exit 2, and leave no row.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from phantomtouch.cli import main
from phantomtouch.service.store import PatternStore

CORPUS = Path(__file__).parent / "samples" / "tact" / "bhaptics-popone-support"
ARMS = {"forearml", "forearmr"}


def raw_arm_length_ms(path: Path) -> tuple[bool, float]:
    """Whether the file has a point above 0 on an arm, and its length, from the raw JSON
    (the corpus spells its keys in camelCase, positions by name)."""
    project = json.loads(path.read_text(encoding="utf-8-sig"))["project"]
    has_arm, length_ms = False, 0.0
    for track in project["tracks"]:
        if track.get("enable") is False:
            continue
        for effect in track["effects"]:
            length_ms = max(length_ms, float(effect["startTime"]) + float(effect["offsetTime"]))
            for position, mode in effect["modes"].items():
                if position.lower() not in ARMS:
                    continue
                chosen = mode["dotMode"] if mode["mode"] == "DOT_MODE" else mode["pathMode"]
                points: list[Any] = []
                for feedback in chosen["feedback"]:
                    points += feedback.get("pointList", [])
                has_arm = has_arm or any(float(p["intensity"]) > 0 for p in points)
    return has_arm, length_ms


def test_every_real_file_is_imported_or_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "library.db"
    expected: dict[str, float] = {}
    files = sorted(CORPUS.rglob("*.tact"))
    assert len(files) == 200
    for path in files:
        has_arm, length_ms = raw_arm_length_ms(path)
        status = main(["import", str(path), "--db", str(db)])
        out, err = capsys.readouterr()
        if has_arm:
            assert status == 0, err
            assert f"'{path.stem}'" in out
            expected[path.stem] = length_ms / 1000.0
        else:
            assert status == 2, out
            assert err.count("\n") == 1 and "no arm content" in err, err
            assert "Traceback" not in err
    assert len(expected) == 44
    store = PatternStore.open(db)
    try:
        listed = store.list_documents("tact", 1000, 0)
    finally:
        store.close()
    assert [name for name, _, _ in listed] == sorted(expected)
    for name, size, summary in listed:
        assert json.loads(summary)["duration_s"] == pytest.approx(expected[name])
        assert size > 0


def test_the_stored_project_reads_back_as_the_file_and_o_writes_the_put_body(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = CORPUS / "Arm" / "RubbingDefib.tact"
    db = tmp_path / "library.db"
    assert main(["import", str(path), "--db", str(db), "--name", "rubbing"]) == 0
    assert main(["import", str(path), "--db", str(db), "--name", "rubbing"]) == 0
    assert "replaced" in capsys.readouterr().out
    store = PatternStore.open(db)
    try:
        stored = store.get_document("tact", "rubbing")
        assert [name for name, _, _ in store.list_documents("tact", 10, 0)] == ["rubbing"]
    finally:
        store.close()
    assert stored is not None
    assert json.loads(stored) == json.loads(path.read_text(encoding="utf-8-sig"))
    out = tmp_path / "rubbing.json"
    assert main(["import", str(path), "-o", str(out)]) == 0
    assert json.loads(out.read_text()) == json.loads(stored)


def test_a_bad_name_or_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "library.db"
    path = CORPUS / "Arm" / "RubbingDefib.tact"
    assert main(["import", str(path), "--db", str(db), "--name", ".."]) == 2
    broken = tmp_path / "broken.tact"
    broken.write_text('{"project": {"tracks": [{"effects": 3}]}}')
    assert main(["import", str(broken), "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert "--name='..'" in err
    assert "tracks[0].effects must be an array" in err
