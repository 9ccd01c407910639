"""POST /touch, POST /stop, GET|DELETE /jobs/{job_id} with the engine running."""

from __future__ import annotations

import time
from pathlib import Path

from fastapi.testclient import TestClient

from phantomtouch.server import create_app
from tests.support.service import LONG, STROKE, make_settings


def test_touch_is_accepted_with_its_plan(client: TestClient) -> None:
    before_s = client.get("/clock").json()["server_time_s"]
    answer = client.post("/touch", json={**STROKE, "start_in_ms": 50})
    after_s = client.get("/clock").json()["server_time_s"]
    assert answer.status_code == 202
    job = answer.json()
    assert job["duration_s"] == 3.12
    assert job["path_length_cm"] == 9.6
    assert job["speed_cm_s"] == 5.0
    assert job["frames"] == 149760
    frame_s = 1 / 48000  # start times are whole frames
    assert before_s + 0.05 - frame_s <= job["start_at_s"] <= after_s + 0.05 + frame_s
    state = client.get(f"/jobs/{job['job_id']}").json()
    assert state["state"] in ("scheduled", "playing")
    assert state["duration_s"] == 3.12


def test_preset_with_overrides_and_stored_pattern(client: TestClient) -> None:
    preset = client.post("/touch", json={"preset": "exp2/curved", "overrides": {"speed_cm_s": 9.6}})
    assert preset.status_code == 202
    assert preset.json()["speed_cm_s"] == 9.6
    assert client.put("/patterns/stroke", json=STROKE).status_code == 200
    stored = client.post("/touch", json={"stored": "stroke"})
    assert stored.status_code == 202
    assert stored.json()["path_length_cm"] == 9.6


def test_pattern_is_a_deprecated_alias_of_stored(client: TestClient) -> None:
    assert client.put("/patterns/stroke", json=STROKE).status_code == 200
    legacy = client.post("/touch", json={"pattern": "stroke", "start_in_ms": 5})
    assert legacy.status_code == 202
    assert legacy.json()["path_length_cm"] == 9.6
    both = client.post("/touch", json={"stored": "stroke", "pattern": "stroke"})
    assert both.status_code == 422
    assert both.json()["error"]["fields"][0]["field"] == "pattern"
    schema = client.get("/openapi.json").json()["components"]["schemas"]
    assert schema["LegacyNamedTouch"]["deprecated"] is True
    assert schema["NamedTouch"]["required"] == ["stored"]


def test_unknown_preset_and_pattern_are_404_naming_the_field(client: TestClient) -> None:
    preset = client.post("/touch", json={"preset": "exp2/curvy"})
    assert preset.status_code == 404
    assert preset.json()["error"]["fields"][0]["field"] == "preset"
    assert "exp2/curved" in preset.json()["error"]["message"], "suggests the close name"
    stored = client.post("/touch", json={"stored": "nope"})
    assert stored.status_code == 404
    assert stored.json()["error"]["fields"][0] == {
        "field": "stored",
        "value": "nope",
        "message": "stored='nope' is not in the pattern library (GET /patterns)",
    }


def test_invalid_touch_names_field_value_and_range(client: TestClient) -> None:
    answer = client.post("/touch", json={**STROKE, "speed_cm_s": 0})
    assert answer.status_code == 422
    assert answer.json() == {
        "error": {
            "code": "invalid",
            "message": "speed_cm_s=0: Input should be greater than 0",
            "fields": [
                {"field": "speed_cm_s", "value": 0, "message": "Input should be greater than 0"}
            ],
        }
    }
    nyquist = client.post("/touch", json={**STROKE, "carrier": {"kind": "sine", "freq_hz": 30000}})
    assert nyquist.status_code == 422
    assert nyquist.json()["error"]["fields"][0]["field"] == "carrier.freq_hz"
    past = client.post("/touch", json={**STROKE, "start_at_s": 1.0})
    assert past.status_code == 422
    assert past.json()["error"]["fields"][0]["field"] == "start_at_s"


def test_delete_job_stops_it(client: TestClient) -> None:
    job = client.post("/touch", json=LONG).json()
    stopped = client.delete(f"/jobs/{job['job_id']}")
    assert stopped.status_code == 200
    assert stopped.json()["state"] == "stopped"
    again = client.delete(f"/jobs/{job['job_id']}")
    assert again.json()["state"] == "stopped"
    missing = client.get("/jobs/0123abc")
    assert missing.status_code == 404
    assert missing.json()["error"]["fields"][0]["field"] == "job_id"


def test_stop_turns_everything_off(client: TestClient) -> None:
    jobs = [client.post("/touch", json=LONG).json()["job_id"] for _ in range(5)]
    answer = client.post("/stop")
    assert answer.status_code == 200
    assert answer.json()["stopped"] is True
    assert {client.get(f"/jobs/{j}").json()["state"] for j in jobs} == {"stopped"}
    engine = client.app.state.service.engine  # type: ignore[attr-defined]
    deadline = time.monotonic() + 5.0
    while engine.status().active_voices and time.monotonic() < deadline:
        time.sleep(0.02)
    assert engine.status().active_voices == 0


def test_full_engine_answers_503_busy(tmp_path: Path) -> None:
    with TestClient(create_app(make_settings(tmp_path, queue_capacity=16))) as client:
        answers = [client.post("/touch", json=LONG) for _ in range(17)]
        assert [a.status_code for a in answers[:16]] == [202] * 16
        busy = answers[16]
        assert busy.status_code == 503
        assert busy.headers["retry-after"] == "1"
        assert busy.json()["error"]["code"] == "busy"
        assert "queue_capacity=16" in busy.json()["error"]["message"]
        assert client.post("/stop").status_code == 200, "stop is never refused"


def test_more_voices_than_max_voices_at_once_answer_503_busy(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, max_voices=2, max_voices_per_client=3, voice_policy="refuse")
    with TestClient(create_app(settings)) as client:
        answers = [client.post("/touch", json=LONG) for _ in range(3)]
        assert [a.status_code for a in answers[:2]] == [202, 202]
        busy = answers[2]
        assert busy.status_code == 503
        assert busy.headers["retry-after"] == "1"
        assert busy.json()["error"]["code"] == "busy"
        assert "the voice budget allows 2" in busy.json()["error"]["message"]
        assert client.post("/stop").status_code == 200


def test_by_default_the_newest_touch_steals_the_oldest(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, max_voices=2, max_voices_per_client=3)
    with TestClient(create_app(settings)) as client:
        jobs = []
        for _ in range(3):
            answer = client.post("/touch", json=LONG)
            assert answer.status_code == 202
            jobs.append(answer.json()["job_id"])
            deadline = time.monotonic() + 10
            while client.get(f"/jobs/{jobs[-1]}").json()["state"] != "playing":
                assert time.monotonic() < deadline
                time.sleep(0.01)
        states = [client.get(f"/jobs/{job}").json()["state"] for job in jobs]
        assert states == ["stopped", "playing", "playing"]


def test_touch_answer_says_how_much_the_ceiling_clips(client: TestClient) -> None:
    quiet = client.post("/touch", json=STROKE).json()
    assert quiet["clipped_fraction"] == 0.0
    loud = {**STROKE, "carrier": {"kind": "noise"}, "level_db": 150.0}
    answer = client.post("/touch", json=loud)
    assert answer.status_code == 202
    # Noise at the device's maximum level drives its peaks past the ceiling.
    assert 0.0 < answer.json()["clipped_fraction"] < 0.05
