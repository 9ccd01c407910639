"""The SDK2 workspace library over REST: store, page, read back, delete, refuse.

The app runs the real engine on the null output and keeps its library in an SQLite file
of the test's folder; deployments are built in the portal's shape from the corpus's real
``.tact`` files (``tests/support/deployments.py``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from phantomtouch.server import create_app
from phantomtouch.service.errors import StoredPatternError
from phantomtouch.service.store import PatternStore
from phantomtouch.service.workspace_library import stored_deployment
from tests.support.deployments import (
    ARM_CLIP,
    BOTH,
    RECOIL,
    VEST_CLIP,
    effects_end_ms,
    mapping,
    portal,
)
from tests.support.service import make_settings

JSON = {"content-type": "application/json"}


def test_store_page_read_back_and_delete(client: TestClient) -> None:
    stored = client.put("/bhaptics/workspaces/ws-123", json=BOTH)
    assert stored.status_code == 200, stored.text
    info = stored.json()
    assert info["workspace_id"] == "ws-123"
    assert info["game"] == "A Game"
    assert info["version"] == 7
    assert (info["events"], info["arm_events"]) == (3, 3)
    assert info["longest_ms"] == max(100, math.ceil(effects_end_ms(RECOIL)), 274)
    back = client.get("/bhaptics/workspaces/ws-123")
    assert back.status_code == 200
    assert back.json() == BOTH
    assert info["bytes"] == len(back.content)
    for k in range(4):
        vest = portal(mapping(f"vest-{k}", clips=[VEST_CLIP]))
        assert client.put(f"/bhaptics/workspaces/game-{k}", json=vest).status_code == 200
    ids = [w["workspace_id"] for w in client.get("/bhaptics/workspaces").json()]
    assert ids == ["game-0", "game-1", "game-2", "game-3", "ws-123"]
    page = client.get("/bhaptics/workspaces", params={"limit": 2, "offset": 1}).json()
    assert [(w["workspace_id"], w["events"], w["arm_events"]) for w in page] == [
        ("game-1", 1, 0),
        ("game-2", 1, 0),
    ]
    assert client.get("/bhaptics/workspaces", params={"offset": 5}).json() == []
    assert client.delete("/bhaptics/workspaces/game-0").status_code == 204
    gone = client.delete("/bhaptics/workspaces/game-0")
    assert gone.status_code == 404
    assert gone.json()["error"]["fields"][0]["field"] == "workspace_id"
    assert client.get("/bhaptics/workspaces/game-0").status_code == 404


def test_a_put_replaces_and_the_path_decides_the_workspace(client: TestClient) -> None:
    client.put("/bhaptics/workspaces/mine", json=BOTH)
    only = portal(mapping("hit", clips=[ARM_CLIP]), workspace="someone-else")
    replaced = client.put("/bhaptics/workspaces/mine", json=only["message"])
    assert replaced.status_code == 200
    assert replaced.json()["events"] == 1
    assert [w["workspace_id"] for w in client.get("/bhaptics/workspaces").json()] == ["mine"]


def test_a_refused_deployment_names_the_field_at_fault(client: TestClient) -> None:
    cases = [
        ({}, "hapticMappings", "hapticMappings must be a list of mappings, got nothing"),
        ({"message": 3}, "message", "message must be an object"),
        (
            portal(mapping("a", eventTime=1.5)),
            "message.hapticMappings[0].eventTime",
            "eventTime=1.5 must be an integer within [0, 600000] ms",
        ),
        (
            portal(mapping("a"), mapping("a")),
            "message.hapticMappings[1].key",
            "repeats message.hapticMappings[0].key",
        ),
        (
            portal(mapping("a", clips=[{"patterns": {"ForearmL": ["AAEC"]}}])),
            "message.hapticMappings[0].audioFilePatterns[0].clip.patterns.ForearmL[0]",
            "decodes to 3 bytes",
        ),
        (
            portal(mapping("a", tact_files=[("Vest", {"tracks": [{"effects": 5}]})])),
            "message.hapticMappings[0].tactFilePatterns[0].tactFile.tracks[0].effects",
            "tracks[0].effects must be an array",
        ),
    ]
    for body, field, words in cases:
        refused = client.put("/bhaptics/workspaces/bad", json=body)
        assert refused.status_code == 422, refused.text
        error = refused.json()["error"]
        assert error["fields"][0]["field"] == field, error
        assert words in error["message"], error
    not_json = client.put("/bhaptics/workspaces/bad", content=b"{nope", headers=JSON)
    assert not_json.status_code == 422
    assert not_json.json()["error"]["fields"][0]["field"] == "body"
    listed = client.put("/bhaptics/workspaces/bad", json=BOTH["message"]["hapticMappings"])
    assert listed.status_code == 422
    assert "must be a JSON object" in listed.json()["error"]["message"]
    assert client.get("/bhaptics/workspaces").json() == []
    assert client.get("/bhaptics/workspaces", params={"limit": 0}).status_code == 422
    assert client.put("/bhaptics/workspaces/..x", json=BOTH).status_code == 200
    assert client.put("/bhaptics/workspaces/a%20b", json=BOTH).status_code == 422


def test_the_workspace_outlives_the_service_and_reads_back_as_its_events(
    tmp_path: Path,
) -> None:
    settings = make_settings(tmp_path)
    with TestClient(create_app(settings)) as client:
        assert client.put("/bhaptics/workspaces/ws-123", json=BOTH).status_code == 200
    store = PatternStore.open(settings.db_path)
    try:
        deployment = stored_deployment(store, "ws-123")
        assert deployment is not None
        assert deployment.event_times() == {
            "recoil": math.ceil(effects_end_ms(RECOIL)),
            "climb": 274,
            "hit": 100,
        }
        assert stored_deployment(store, "nobody") is None
        store.put_document("workspaces", "damaged", '{"hapticMappings": 3}', {})
        with pytest.raises(StoredPatternError, match="PUT it again or DELETE it"):
            stored_deployment(store, "damaged")
    finally:
        store.close()
    with TestClient(create_app(settings)) as client:
        assert json.loads(client.get("/bhaptics/workspaces/ws-123").content) == BOTH
