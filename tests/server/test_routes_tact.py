"""The ``.tact`` library over REST and ``/ws``: store, page, read back, play, refuse.

The app runs the real engine on the null output and keeps its library in an SQLite file
of the test's folder. The projects are real files of the corpus (MIT) or a one-dot project
written here from the format's description (docs/bhaptics.md).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from phantomtouch.server import create_app
from tests.support.service import make_settings

CORPUS = Path(__file__).parents[1] / "clips" / "samples" / "tact" / "bhaptics-popone-support"
RUBBING = (CORPUS / "Arm" / "RubbingDefib.tact").read_bytes()
"""1 s long, six voices on both arms (its latest effect ends at 1000 ms)."""
JSON = {"content-type": "application/json"}


def one_dot(position: str, length_ms: int) -> dict[str, Any]:
    """A project with one dot on for ``length_ms`` at ``position``."""
    feedback = {
        "startTime": 0,
        "endTime": length_ms,
        "playbackType": "NONE",
        "pointList": [{"index": 1, "intensity": 1.0}],
    }
    mode = {"mode": "DOT_MODE", "dotMode": {"feedback": [feedback]}, "pathMode": {}}
    effect = {"startTime": 0, "offsetTime": length_ms, "modes": {position: mode}}
    return {"project": {"tracks": [{"effects": [effect]}], "layout": {}}}


def test_store_page_read_back_and_delete(client: TestClient) -> None:
    assert client.get("/tact").json() == []
    stored = client.put("/tact/rubbing", content=RUBBING, headers=JSON)
    assert stored.status_code == 200, stored.text
    info = stored.json()
    assert info["duration_s"] == 1.0
    assert info["positions"] == ["ForearmL", "ForearmR"]
    assert info["bytes"] == len(client.get("/tact/rubbing").content)
    assert client.get("/tact/rubbing").json() == json.loads(RUBBING.decode("utf-8-sig"))
    for k in range(5):
        body = one_dot("ForearmR", 100 * (k + 1))
        assert client.put(f"/tact/dot-{k}", json=body).status_code == 200
    names = [p["name"] for p in client.get("/tact", params={"limit": 1000}).json()]
    assert names == ["dot-0", "dot-1", "dot-2", "dot-3", "dot-4", "rubbing"]
    page = client.get("/tact", params={"limit": 2, "offset": 3}).json()
    assert [(p["name"], p["duration_s"]) for p in page] == [("dot-3", 0.4), ("dot-4", 0.5)]
    assert client.get("/tact", params={"offset": 6}).json() == []
    assert client.delete("/tact/dot-0").status_code == 204
    assert client.delete("/tact/dot-0").status_code == 404
    missing = client.get("/tact/dot-0")
    assert missing.status_code == 404
    assert missing.json()["error"]["fields"][0]["field"] == "name"


def test_what_is_no_arm_project_is_refused_naming_why(client: TestClient) -> None:
    vest = client.put("/tact/vest", json=one_dot("VestFront", 200))
    assert vest.status_code == 422
    assert "no arm content: it plays on VestFront" in vest.json()["error"]["message"]
    assert vest.json()["error"]["fields"][0]["field"] == "project.tracks"
    bare = client.put("/tact/bare", json={"Tracks": []})  # the project object, no content
    assert bare.status_code == 422
    assert bare.json()["error"]["fields"][0]["field"] == "Tracks"
    assert "no arm content: it plays on none" in bare.json()["error"]["message"]
    empty = client.put("/tact/empty", json={})
    assert empty.json()["error"]["fields"][0]["field"] == "tracks"
    wrong = client.put("/tact/bad", json={"project": {"tracks": [{"effects": "x"}]}})
    assert wrong.status_code == 422
    assert "project.tracks[0].effects must be an array" in wrong.json()["error"]["message"]
    assert wrong.json()["error"]["fields"][0]["field"] == "project.tracks[0].effects"
    not_json = client.put("/tact/bad", content=b"{nope", headers=JSON)
    assert not_json.status_code == 422
    assert "not JSON" in not_json.json()["error"]["message"]
    assert not_json.json()["error"]["fields"][0]["field"] == "body"
    assert client.get("/tact").json() == []
    limits = client.get("/tact", params={"limit": 0})
    assert limits.status_code == 422
    assert limits.json()["error"]["fields"][0]["field"] == "limit"


def test_play_schedules_every_voice_for_the_stretched_length(client: TestClient) -> None:
    client.put("/tact/rubbing", content=RUBBING, headers=JSON)
    played = client.post("/tact/rubbing/play", json={"duration_scale": 2, "start_in_ms": 200})
    assert played.status_code == 202, played.text
    answer = played.json()
    assert answer["duration_s"] == 2.0
    jobs = [client.get(f"/jobs/{job}").json() for job in answer["job_ids"]]
    assert len(jobs) == 6
    # every voice within the project's stretched length, from the play's start frame
    assert min(j["start_frame"] for j in jobs) == answer["start_frame"]
    last_end = max(j["start_frame"] + j["duration_s"] * 48000 for j in jobs)
    assert abs(last_end - answer["start_frame"] - 2.0 * 48000) <= 0.04 * 48000
    refused = client.post("/tact/rubbing/play", json={"duration_scale": 1000})
    assert refused.status_code == 422
    assert refused.json()["error"]["fields"][0]["field"] == "duration_scale"
    assert client.post("/tact/nothing/play").status_code == 404


def test_a_project_plays_whole_or_not_at_all_under_the_quota(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, max_voices_per_client=4)
    with TestClient(create_app(settings)) as client:
        client.put("/tact/rubbing", content=RUBBING, headers=JSON)
        refused = client.post("/tact/rubbing/play")
        assert refused.status_code == 429
        assert refused.json()["error"]["code"] == "quota"
        # the voices scheduled before the refusal were stopped: the client holds none
        assert client.post("/touch", json={"preset": "vr/tap"}).status_code == 202
        small = client.put("/tact/small", json=one_dot("ForearmL", 300))
        assert small.status_code == 200
        assert client.post("/tact/small/play").status_code == 202


def test_the_websocket_plays_a_stored_project_by_name(client: TestClient) -> None:
    client.put("/tact/rubbing", content=RUBBING, headers=JSON)
    with client.websocket_connect("/ws") as ws:
        ws.send_text(json.dumps({"type": "play", "id": 1, "tact": "rubbing"}))
        ok = ws.receive_json()
        assert ok["type"] == "ok" and ok["id"] == 1
        assert ok["result"]["name"] == "rubbing" and len(ok["result"]["job_ids"]) == 6
        ws.send_text(json.dumps({"type": "play", "id": 2, "tact": "gone"}))
        missing = ws.receive_json()
        assert (missing["code"], missing["fields"][0]["field"]) == ("not_found", "tact")
        ws.send_text(json.dumps({"type": "play", "id": 3, "tact": "rubbing", "speed": 2}))
        extra = ws.receive_json()
        assert extra["type"] == "error" and extra["fields"][0]["field"] == "speed"


def test_the_schema_documents_the_tact_routes(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    assert set(paths["/tact"]) == {"get"}
    assert set(paths["/tact/{name}"]) == {"get", "put", "delete"}
    play = paths["/tact/{name}/play"]["post"]
    assert set(play["responses"]) >= {"202", "404", "422", "429"}
    body = play["requestBody"]["content"]["application/json"]["schema"]["properties"]
    assert {"intensity_scale", "duration_scale", "start_in_ms", "start_at_s"} <= set(body)
    put = paths["/tact/{name}"]["put"]["requestBody"]["content"]["application/json"]
    assert put["schema"]["type"] == "object" and "example" in put
