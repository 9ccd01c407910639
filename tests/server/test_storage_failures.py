"""The pattern store failing while a real server runs: a full disk, a damaged page.

The full disk is a small tmpfs mounted for the test and unmounted after it (the tests
run as root, as ``scripts/test`` does); the damaged page is written into the SQLite file
of a running server. Either way every answer is JSON, the refusal is 503 ``storage``
naming the cause, and ``/health`` says ``degraded`` and why.
"""

from __future__ import annotations

import contextlib
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from phantomtouch import plan
from phantomtouch.schema import TouchPattern
from phantomtouch.service.store import PatternStore
from tests.support.live_server import LiveServer
from tests.support.service import STROKE

PAGE_BYTES = 4096


def padded(k: int) -> dict[str, object]:
    """A stroke whose path has 200 points (a few kB stored), distinct for each ``k``."""
    points = [[1.9, 2.4 + 0.04 * j + 1e-6 * k] for j in range(200)]
    return {**STROKE, "path": {"kind": "polyline", "points_cm": points}}


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 256 KiB tmpfs, unmounted after the test."""
    mount_point = tmp_path / "small"
    mount_point.mkdir()
    subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mount_point)], check=True
    )
    try:
        yield mount_point
    finally:
        subprocess.run(["umount", "-l", str(mount_point)], check=True)


def test_a_full_disk_answers_503_storage_and_health_degraded(
    small_disk: Path, tmp_path: Path
) -> None:
    with (
        LiveServer(small_disk / "patterns.db", log_path=tmp_path / "server.log") as server,
        httpx.Client(base_url=server.url, timeout=10) as client,
    ):
        assert client.get("/health").json()["status"] == "ok"
        answers = []
        for k in range(400):  # 256 KiB hold fewer than 100 of them
            answer = client.put(f"/patterns/p{k}", json=padded(k))
            answers.append(answer.status_code)
            if answer.status_code != 200:
                break
        assert answers[0] == 200 and answers[-1] == 503, answers
        error = answer.json()["error"]
        assert error["code"] == "storage"
        assert "disk is full" in error["message"]
        health = client.get("/health").json()
        assert health["status"] == "degraded"
        assert "disk is full" in health["storage"]
        listed = client.get("/patterns")
        assert listed.status_code == 200, "what was stored is still served"
        assert len(listed.json()) == answers.count(200)
        log = server.log()
    assert "Traceback" not in log


def test_serve_on_a_full_disk_exits_naming_the_full_disk_in_one_line(small_disk: Path) -> None:
    # A library written earlier; then the disk fills up (SQLite then cannot create its
    # shared-memory file and says only "disk I/O error").
    db = small_disk / "patterns.db"
    connection = sqlite3.connect(db)
    connection.execute("PRAGMA journal_mode=WAL")
    connection.execute("CREATE TABLE earlier (a)")
    connection.close()
    with contextlib.suppress(OSError), (small_disk / "filler").open("wb") as filler:
        while True:
            filler.write(b"\0" * 4096)
            filler.flush()
    done = subprocess.run(
        [sys.executable, "-m", "phantomtouch", "serve", "--output", "null", "--db", str(db)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "disk is full" in lines[0]
    assert str(small_disk) in lines[0]


def test_a_damaged_page_answers_503_storage_and_health_degraded(tmp_path: Path) -> None:
    db_path = tmp_path / "patterns.db"
    store = PatternStore.open(db_path)
    for k in range(60):
        pattern = TouchPattern.model_validate(padded(k))
        store.put(f"p{k}", pattern, plan(pattern).summary())
    store.close()  # the last connection: the journal is folded into the file
    with sqlite3.connect(db_path) as check:
        pages = check.execute("PRAGMA page_count").fetchone()[0]
    assert pages > 10
    with (
        LiveServer(db_path) as server,
        httpx.Client(base_url=server.url, timeout=10) as client,
    ):
        with db_path.open("r+b") as file:  # every page but the schema's, while it runs
            file.seek(PAGE_BYTES)
            file.write(b"\xa5" * PAGE_BYTES * (pages - 1))
        listed = client.get("/patterns")
        assert listed.status_code == 503
        error = listed.json()["error"]
        assert error["code"] == "storage"
        assert "damaged" in error["message"]
        one = client.get("/patterns/p3")
        assert (one.status_code, one.json()["error"]["code"]) == (503, "storage")
        health = client.get("/health").json()
        assert health["status"] == "degraded"
        assert "damaged" in health["storage"]
        assert client.post("/touch", json={"preset": "vr/tap"}).status_code == 202
        log = server.log()
    assert "Traceback" not in log
