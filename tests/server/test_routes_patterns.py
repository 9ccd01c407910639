"""The pattern library over REST: GET /patterns, GET|PUT|DELETE /patterns/{name}, play."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from phantomtouch.server import create_app
from phantomtouch.service.settings import Settings
from tests.support.service import STROKE, make_settings


def test_put_get_list_delete(client: TestClient) -> None:
    assert client.get("/patterns").json() == []
    stored = client.put("/patterns/my-stroke.v1", json=STROKE)
    assert stored.status_code == 200
    assert stored.json()["summary"]["duration_s"] == 3.12
    assert client.get("/patterns/my-stroke.v1").json() == {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 5.0,
    }
    listed = client.get("/patterns").json()
    assert [(p["name"], p["summary"]["path_length_cm"]) for p in listed] == [("my-stroke.v1", 9.6)]
    assert client.delete("/patterns/my-stroke.v1").status_code == 204
    gone = client.get("/patterns/my-stroke.v1")
    assert gone.status_code == 404
    assert gone.json()["error"]["fields"][0]["field"] == "name", "the path's name, as DELETE"
    deleted_again = client.delete("/patterns/my-stroke.v1")
    assert deleted_again.status_code == 404
    assert deleted_again.json()["error"]["fields"][0]["field"] == "name"


def test_names_from_a_safe_set(client: TestClient) -> None:
    for name in ("a b", "x" * 65, "semi;colon", "caf\u00e9"):
        answer = client.put(f"/patterns/{name}", json=STROKE)
        assert answer.status_code == 422, name
        assert answer.json()["error"]["fields"][0]["field"] == "name"


@pytest.mark.parametrize("name", [".", ".."])
def test_dot_segments_are_not_names(client: TestClient, name: str) -> None:
    encoded = name.replace(".", "%2E")
    answer = client.put(f"/patterns/{encoded}", json=STROKE)
    assert answer.status_code == 422, "a client that normalises URLs could never reach it"
    assert answer.json()["error"]["fields"][0]["field"] == "name"
    touch = client.post("/touch", json={"stored": name})
    assert touch.status_code == 422
    assert touch.json()["error"]["fields"][0]["field"] == "stored"


@pytest.mark.parametrize("name", [".a", "..a", "...", "a..", "-", "a" * 64, ".." + "a" * 62])
def test_names_with_dots_that_are_not_dot_segments(client: TestClient, name: str) -> None:
    assert client.put(f"/patterns/{name}", json=STROKE).status_code == 200, name
    assert client.get(f"/patterns/{name}").status_code == 200


def test_unreadable_row_is_a_server_error_and_the_rest_stays_usable(
    client: TestClient, settings: Settings
) -> None:
    client.put("/patterns/good", json=STROKE)
    client.put("/patterns/bad", json=STROKE)
    with sqlite3.connect(settings.db_path) as db:
        db.execute("UPDATE patterns SET pattern = '{\"speed_cm_s\": 5}' WHERE name = 'bad'")
    assert [p["name"] for p in client.get("/patterns").json()] == ["good"]
    for answer in (
        client.get("/patterns/bad"),
        client.post("/patterns/bad/play"),
        client.post("/touch", json={"pattern": "bad"}),
    ):
        assert answer.status_code == 500
        error = answer.json()["error"]
        assert error["code"] == "stored_pattern"
        assert "pattern='bad': the stored row no longer reads as a pattern" in error["message"]
    assert client.post("/patterns/good/play").status_code == 202
    assert client.put("/patterns/bad", json=STROKE).status_code == 200, "PUT mends it"
    assert [p["name"] for p in client.get("/patterns").json()] == ["bad", "good"]
    client.post("/stop")


def test_only_playable_patterns_are_stored(client: TestClient) -> None:
    unplayable = {**STROKE, "carrier": {"kind": "sine", "freq_hz": 25000}}
    answer = client.put("/patterns/too-high", json=unplayable)
    assert answer.status_code == 422
    assert answer.json()["error"]["fields"][0]["field"] == "carrier.freq_hz"
    strict = client.put("/patterns/strict", json={**STROKE, "speed_cm_s": "5"})
    assert strict.status_code == 422, "numbers must be numbers"
    assert client.get("/patterns").json() == []


def test_play_with_and_without_timing(client: TestClient) -> None:
    client.put("/patterns/stroke", json=STROKE)
    plain = client.post("/patterns/stroke/play")
    assert plain.status_code == 202
    assert plain.json()["duration_s"] == 3.12
    timed = client.post("/patterns/stroke/play", json={"start_in_ms": 500})
    assert timed.status_code == 202
    state = client.get(f"/jobs/{timed.json()['job_id']}").json()
    assert state["state"] == "scheduled"
    unknown = client.post("/patterns/nope/play")
    assert unknown.status_code == 404


def test_library_outlives_the_app(tmp_path: Path) -> None:
    settings = make_settings(tmp_path)
    with TestClient(create_app(settings)) as client:
        client.put("/patterns/kept", json=STROKE)
    with TestClient(create_app(settings)) as client:
        assert [p["name"] for p in client.get("/patterns").json()] == ["kept"]
