"""Who may do what: player tokens at a gateway, NATS credentials from the environment."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from phantomtouch.fleet.settings import FleetSettings
from tests.fleet.conftest import Fleet
from tests.support.fleet import ArmbandNode, Gateway
from tests.support.nats_cluster import NatsCluster
from tests.support.service import LONG, STROKE
from tests.support.waiting import wait_until

ALICE = "alice-token-0123456789"
OPS = "operator-token-0123456789"
TOKENS = {
    ALICE: {"player": "alice", "armbands": ["a1", "a2"]},
    OPS: {"player": "ops", "armbands": "*"},
}


@pytest.fixture(scope="module")
def guarded(fleet: Fleet) -> Iterator[Gateway]:
    env = {"PHANTOMTOUCH_GATEWAY_TOKENS": json.dumps(TOKENS)}
    gateway = Gateway(fleet.folder, fleet.cluster, env=env).start()
    yield gateway
    gateway.stop()


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_a_gateway_with_tokens_refuses_a_request_without_one(guarded: Gateway) -> None:
    answer = httpx.post(f"{guarded.url}/armbands/a1/touch", json=STROKE)
    assert answer.status_code == 401
    assert httpx.get(f"{guarded.url}/armbands").status_code == 401
    wrong = httpx.get(f"{guarded.url}/armbands", headers=_bearer("not-a-token-of-anyone"))
    assert wrong.status_code == 401
    assert httpx.get(f"{guarded.url}/health").status_code == 200


def test_a_player_touches_and_lists_only_their_armbands(guarded: Gateway) -> None:
    url = guarded.url
    mine = httpx.post(f"{url}/armbands/a2/touch", json=STROKE, headers=_bearer(ALICE))
    assert mine.status_code == 202, mine.text
    theirs = httpx.post(f"{url}/armbands/a3/touch", json=STROKE, headers=_bearer(ALICE))
    assert theirs.status_code == 403
    assert theirs.json()["error"]["code"] == "forbidden"
    assert "armband='a3'" in theirs.json()["error"]["message"]
    listed = httpx.get(f"{url}/armbands", headers=_bearer(ALICE)).json()
    assert sorted(r["armband"] for r in listed) == ["a1", "a2"]
    everyone = httpx.get(f"{url}/armbands", headers=_bearer(OPS)).json()
    assert sorted(r["armband"] for r in everyone) == ["a1", "a2", "a3"]


def test_a_players_stop_all_stops_only_their_armbands(fleet: Fleet, guarded: Gateway) -> None:
    jobs = {}
    for armband in ("a1", "a2", "a3"):
        answer = httpx.post(
            f"{guarded.url}/armbands/{armband}/touch", json=LONG, headers=_bearer(OPS)
        )
        assert answer.status_code == 202
        jobs[armband] = answer.json()["job_id"]
    answer = httpx.post(f"{guarded.url}/stop", json={"scope": "all"}, headers=_bearer(ALICE))
    assert answer.json()["stopped"] == ["a1", "a2"]
    states = {
        a: httpx.get(f"{fleet.nodes[a].url}/jobs/{job}").json()["state"] for a, job in jobs.items()
    }
    assert states["a1"] == states["a2"] == "stopped"
    assert states["a3"] in ("scheduled", "playing")
    httpx.post(f"{guarded.url}/stop", headers=_bearer(OPS))


def test_the_websocket_needs_a_token_and_keeps_to_its_scope(guarded: Gateway) -> None:
    with connect(guarded.ws_url) as ws:
        with pytest.raises(ConnectionClosed) as closed:
            ws.recv(timeout=5.0)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    with connect(f"{guarded.ws_url}?token={ALICE}") as ws:
        down = {"type": "down", "armband": "a3", "contact": "c", "x_cm": 1.0, "y_cm": 1.0, "id": 1}
        ws.send(json.dumps(down))
        answer = json.loads(ws.recv(timeout=5.0))
        assert answer["code"] == "forbidden"
        assert "armband='a3'" in answer["message"]


def test_the_url_may_not_carry_nats_credentials() -> None:
    with pytest.raises(ValueError, match="must not carry credentials"):
        FleetSettings(servers=["nats://fleet:hunter2-secret@127.0.0.1:4222"])


def test_nats_credentials_come_from_the_environment_and_stay_out_of_logs(tmp_path: Path) -> None:
    password = "pw-that-must-never-be-logged-7f3a"
    with NatsCluster(tmp_path / "nats", size=1, user="fleet", password=password) as cluster:
        credentials = {"PHANTOMTOUCH_FLEET_USER": "fleet", "PHANTOMTOUCH_FLEET_PASSWORD": password}
        refused = Gateway(tmp_path, cluster)
        with pytest.raises(RuntimeError, match="gateway exited"):
            refused.start()
        node = ArmbandNode(tmp_path, cluster, "solo", "lab", env=credentials)
        node.start()
        gateway = Gateway(tmp_path, cluster, env=credentials).start()
        try:
            wait_until(
                lambda: (
                    [r["armband"] for r in httpx.get(f"{gateway.url}/armbands").json()] == ["solo"]
                ),
                30.0,
                "the node registered",
            )
            answer = httpx.post(f"{gateway.url}/armbands/solo/touch", json=STROKE)
            assert answer.status_code == 202
        finally:
            gateway.stop()
            node.stop()
        for log in (node.log(), gateway.log(), refused.log()):
            assert password not in log
        assert "accepted the connection" in refused.log()


def test_subscribe_pushes_the_state_of_the_players_armbands_only(guarded: Gateway) -> None:
    with connect(f"{guarded.ws_url}?token={ALICE}") as ws:
        ws.send(json.dumps({"type": "subscribe", "armband": "a3", "rate_hz": 20, "id": 1}))
        refused = json.loads(ws.recv(timeout=5.0))
        assert (refused["type"], refused["code"], refused["id"]) == ("error", "forbidden", 1)
        ws.send(json.dumps({"type": "subscribe", "rate_hz": 20, "id": 2}))
        played = httpx.post(
            f"{guarded.url}/armbands/a1/touch", json=LONG, headers=_bearer(ALICE), timeout=5.0
        )
        assert played.status_code == 202, played.text
        busy = False
        for _ in range(100):
            message = json.loads(ws.recv(timeout=5.0))
            if message["type"] != "state":
                assert message == {"type": "ok", "id": 2}
                continue
            assert sorted(a["armband"] for a in message["armbands"]) == ["a1", "a2"]
            loads = {a["armband"]: a["load"] for a in message["armbands"]}
            if loads["a1"]["active_voices"] >= 1:
                busy = True
                break
        assert busy, "a1's playing touch never showed in its state"
        ws.send(json.dumps({"type": "stop", "armband": "a1", "id": 3}))
