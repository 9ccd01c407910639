"""Wearer profiles over REST: stored, listed, removed; bad ones refused naming the field;
the one named at start-up applied by the output stage and shown in /health."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from phantomtouch.errors import DeviceError
from phantomtouch.renderer import OutputStage
from phantomtouch.schema import DeviceProfile, limits
from phantomtouch.schema.wearer import CHANNEL_REGEX, WearerProfile
from phantomtouch.server import create_app
from phantomtouch.server.serve import check_library
from phantomtouch.service.store import PatternStore
from phantomtouch.service.wearers import wearer_gains
from tests.support.service import make_settings

PROFILE: dict[str, Any] = {
    "offsets_db": {
        "sine_100hz": {"1": 0.0, "2": 2.5, "3": -1.5, "8": 6.0},
        "noise_40_500hz": {"2": 1.0},
    },
    "note": "left forearm",
}


def test_put_get_list_delete(client: TestClient) -> None:
    assert client.get("/wearers").json() == []
    stored = client.put("/wearers/participant-07", json=PROFILE)
    assert stored.status_code == 200, stored.text
    assert stored.json() == PROFILE
    assert client.get("/wearers/participant-07").json() == PROFILE
    listed = client.get("/wearers").json()
    assert listed == [{"name": "participant-07", "active": False, "profile": PROFILE}]
    assert client.delete("/wearers/participant-07").status_code == 204
    gone = client.get("/wearers/participant-07")
    assert gone.status_code == 404
    assert gone.json()["error"]["fields"][0]["field"] == "name"
    assert client.delete("/wearers/participant-07").status_code == 404


@pytest.mark.parametrize(
    ("body", "field", "words"),
    [
        ({"offsets_db": {"sine_100hz": {"2": 20.5}}}, "offsets_db.sine_100hz.2", "20"),
        ({"offsets_db": {"noise_40_500hz": {"4": -21}}}, "offsets_db.noise_40_500hz.4", "-20"),
        ({"offsets_db": {"sine_100hz": {"65": 1.0}}}, "offsets_db.sine_100hz.65", "pattern"),
        (
            {"offsets_db": {"sine_100hz": {"one": 1.0}}},
            "offsets_db.sine_100hz.one",
            "pattern",
        ),
        ({"offsets_db": {"square_50hz": {"1": 1.0}}}, "offsets_db.square_50hz", "sine"),
        ({"offsets_db": {}, "gain": 2}, "gain", "not permitted"),
    ],
)
def test_a_bad_profile_is_refused_naming_the_field(
    client: TestClient, body: dict[str, Any], field: str, words: str
) -> None:
    answer = client.put("/wearers/bad", json=body)
    assert answer.status_code == 422, answer.text
    problem = answer.json()["error"]["fields"][0]
    assert problem["field"] == field
    assert words in problem["message"] + answer.json()["error"]["message"]
    assert client.get("/wearers/bad").status_code == 404


def test_nan_is_refused_naming_the_field(client: TestClient) -> None:
    answer = client.put(
        "/wearers/bad",
        content=b'{"offsets_db": {"sine_100hz": {"3": NaN}}}',
        headers={"content-type": "application/json"},
    )
    assert answer.status_code == 422, answer.text
    problem = answer.json()["error"]["fields"][0]
    assert problem["field"] == "offsets_db.sine_100hz.3"
    assert "finite" in problem["message"]


def test_an_actuator_the_device_lacks_is_refused(client: TestClient) -> None:
    answer = client.put("/wearers/bad", json={"offsets_db": {"sine_100hz": {"9": 2.0}}})
    assert answer.status_code == 422, answer.text
    problem = answer.json()["error"]["fields"][0]
    assert problem["field"] == "offsets_db.sine_100hz.9"
    assert problem["value"] == 2.0
    assert "1 to 8" in problem["message"]


def test_the_fitted_output_stage_gains_are_the_calibration_times_the_offsets() -> None:
    levels = (155.0, 153.0, 157.5, 155.0, 150.0, 160.0, 155.0, 154.0)
    device = DeviceProfile.default().model_copy(
        update={
            "calibration": DeviceProfile.default().calibration.model_copy(
                update={"channel_level_db": levels}
            )
        }
    )
    profile = WearerProfile.model_validate(PROFILE)
    for band in ("sine_100hz", "noise_40_500hz"):
        fitted = OutputStage.channel_gains(device) * wearer_gains(device, profile, band)  # type: ignore[arg-type]
        offsets = np.array(profile.channel_offsets_db(band, 8))  # type: ignore[arg-type]
        np.testing.assert_allclose(
            fitted,
            OutputStage.channel_gains(device) * 10.0 ** (offsets / 20.0),
            rtol=1e-12,
        )


def test_health_names_the_wearer_the_service_started_with(tmp_path: Path) -> None:
    settings = make_settings(tmp_path)
    store = PatternStore.open(settings.db_path)
    store.put_wearer("ann", WearerProfile.model_validate(PROFILE))
    store.close()
    with TestClient(create_app(make_settings(tmp_path, wearer="ann"))) as client:
        health = client.get("/health").json()
        assert health["wearer"] == "ann"
        assert health["wearer_band"] == "sine_100hz"
        assert client.get("/wearers").json()[0]["active"] is True
    with TestClient(create_app(settings)) as client:
        assert "wearer" not in client.get("/health").json()


def test_a_wearer_not_in_the_library_stops_the_start(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, wearer="nobody")
    with pytest.raises(DeviceError, match="wearer='nobody' is not in the library"):
        check_library(settings)


def test_the_profile_api_is_in_openapi_with_an_example(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    assert set(paths["/wearers/{name}"]) == {"get", "put", "delete"}
    assert "get" in paths["/wearers"]
    body = paths["/wearers/{name}"]["put"]["requestBody"]["content"]["application/json"]
    WearerProfile.model_validate(body["example"])


def test_the_channel_keys_are_exactly_the_channels_a_device_may_have() -> None:
    accepted = {
        key
        for key in [str(n) for n in range(0, 200)] + ["01", "1.0", " 1", "+1"]
        if re.fullmatch(CHANNEL_REGEX, key)
    }
    assert accepted == {str(n) for n in range(1, limits.MAX_CHANNEL + 1)}


def test_the_wearer_in_force_follows_its_profile_and_the_hello(client: TestClient) -> None:
    assert client.get("/wearer").json() == {"name": None, "band": None, "offsets_db": [0.0] * 8}
    assert client.put("/wearers/ann", json=PROFILE).status_code == 200
    chosen = client.put("/wearer", json={"name": "ann", "band": "noise_40_500hz"})
    assert chosen.status_code == 200, chosen.text
    assert chosen.json()["offsets_db"] == pytest.approx([0, 1.0, 0, 0, 0, 0, 0, 0], abs=1e-6)
    assert [w["active"] for w in client.get("/wearers").json()] == [True]
    # storing the profile in force re-applies it
    changed = {"offsets_db": {"noise_40_500hz": {"3": -4.0}}}
    assert client.put("/wearers/ann", json=changed).status_code == 200
    now = client.get("/wearer").json()
    assert now["offsets_db"] == pytest.approx([0, 0, -4.0, 0, 0, 0, 0, 0], abs=1e-6)
    # a refused choice names the field and keeps the wearer in force
    for body, field in (({"name": "nobody"}, "name"), ({"name": "ann", "band": "x"}, "band")):
        refused = client.put("/wearer", json=body)
        assert refused.status_code == 422, refused.text
        assert refused.json()["error"]["fields"][0]["field"] == field
    assert client.get("/health").json()["wearer"] == "ann"
    # a hello naming a wearer chooses it (or is refused naming the field)
    assert client.put("/wearers/bob", json=PROFILE).status_code == 200
    with client.websocket_connect("/ws") as ws:
        ws.send_json({"type": "hello", "wearer": "nobody", "id": 1})
        error = ws.receive_json()
        assert error["type"] == "error" and "wearer='nobody'" in error["message"]
        ws.send_json({"type": "hello", "wearer": "bob", "id": 2})
        assert ws.receive_json()["wearer"] == {"name": "bob", "band": "sine_100hz"}
    health = client.get("/health").json()
    assert (health["wearer"], health["wearer_band"]) == ("bob", "sine_100hz")
    # removing the profile in force takes it off
    assert client.delete("/wearers/bob").status_code == 204
    assert "wearer" not in client.get("/health").json()
    assert client.get("/wearer").json()["offsets_db"] == [0.0] * 8
    assert client.put("/wearer", json={"name": "ann"}).status_code == 200
    assert client.delete("/wearer").status_code == 204
    assert "wearer" not in client.get("/health").json()
