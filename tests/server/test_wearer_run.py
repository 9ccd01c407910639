"""The answers of a wearer's matching run over REST: stored as they come, read back to
resume, removed; bad ones refused naming the field; never applied by the output stage;
and GET /device names the ceiling the page clamps its levels to."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from phantomtouch.schema import DeviceProfile
from phantomtouch.schema.wearer import MAX_RUN_TRIALS

RUN: dict[str, Any] = {
    "band": "sine_100hz",
    "reference_channel": 1,
    "trials": [
        {"channel": 2, "level_db": 0.0, "test_stronger": False},
        {"channel": 2, "level_db": 4.0, "test_stronger": False},
        {"channel": 2, "level_db": 8.0, "test_stronger": True},
    ],
}


def test_a_run_is_stored_grown_read_back_and_removed(client: TestClient) -> None:
    assert client.get("/wearers/ann/run").status_code == 404
    first = {**RUN, "trials": RUN["trials"][:1]}
    assert client.put("/wearers/ann/run", json=first).json() == first
    assert client.put("/wearers/ann/run", json=RUN).status_code == 200
    assert client.get("/wearers/ann/run").json() == RUN
    assert client.get("/wearers/ann").status_code == 404, "a run is not a profile"
    assert client.get("/wearers").json() == []
    assert client.get("/wearer").json()["offsets_db"] == [0.0] * 8, "a run is never applied"
    assert client.delete("/wearers/ann/run").status_code == 204
    gone = client.get("/wearers/ann/run")
    assert gone.status_code == 404
    assert gone.json()["error"]["fields"][0]["field"] == "name"
    assert client.delete("/wearers/ann/run").status_code == 404


def test_the_run_outlives_a_restart(client: TestClient, settings: Any) -> None:
    from phantomtouch.server import create_app

    assert client.put("/wearers/ann/run", json=RUN).status_code == 200
    with TestClient(create_app(settings)) as again:
        assert again.get("/wearers/ann/run").json() == RUN


@pytest.mark.parametrize(
    ("trial", "field", "words"),
    [
        ({"channel": 9, "level_db": 0.0, "test_stronger": True}, "trials[1].channel", "1 to 8"),
        ({"channel": 0, "level_db": 0.0, "test_stronger": True}, "trials[1].channel", "1"),
        ({"channel": 2, "level_db": 20.5, "test_stronger": True}, "trials[1].level_db", "20"),
        (
            {"channel": 2, "level_db": 1.0, "test_stronger": "yes"},
            "trials[1].test_stronger",
            "bool",
        ),
        ({"channel": 2, "level_db": 1.0}, "trials[1].test_stronger", "required"),
    ],
)
def test_a_bad_trial_is_refused_naming_the_field(
    client: TestClient, trial: dict[str, Any], field: str, words: str
) -> None:
    body = {**RUN, "trials": [RUN["trials"][0], trial]}
    answer = client.put("/wearers/bad/run", json=body)
    assert answer.status_code == 422, answer.text
    problem = answer.json()["error"]["fields"][0]
    assert problem["field"] == field
    assert words in problem["message"] + answer.json()["error"]["message"]
    assert client.get("/wearers/bad/run").status_code == 404


def test_a_reference_the_device_lacks_and_too_many_trials_are_refused(client: TestClient) -> None:
    answer = client.put("/wearers/bad/run", json={**RUN, "reference_channel": 9})
    assert answer.status_code == 422
    assert answer.json()["error"]["fields"][0]["field"] == "reference_channel"
    many = {**RUN, "trials": RUN["trials"][:1] * (MAX_RUN_TRIALS + 1)}
    answer = client.put("/wearers/bad/run", json=many)
    assert answer.status_code == 422
    assert answer.json()["error"]["fields"][0]["field"] == "trials"


def test_the_device_names_its_ceiling(client: TestClient) -> None:
    device = client.get("/device").json()
    assert device["max_level_db"] == DeviceProfile.default().safety.max_level_db
    at_ceiling = {
        "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
        "duration_s": 0.05,
        "fade_in_s": 0.01,
        "fade_out_s": 0.01,
        "level_db": device["max_level_db"],
    }
    assert client.post("/touch", json=at_ceiling).status_code == 202
    above = client.post("/touch", json={**at_ceiling, "level_db": device["max_level_db"] + 0.01})
    assert above.status_code == 422
    assert "max_level_db=150" in above.json()["error"]["message"]
