"""Live contacts through a gateway: latest position wins, and nothing outlives its client."""

from __future__ import annotations

import contextlib
import json
import time
from typing import Any

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from tests.fleet.conftest import Fleet
from tests.support.fleet import WATCHDOG_S, Gateway
from tests.support.waiting import wait_until
from tests.support.yardstick import WakeUpLag


def _ask(ws: ClientConnection, message: dict[str, Any]) -> dict[str, Any]:
    ws.send(json.dumps(message))
    answer: dict[str, Any] = json.loads(ws.recv(timeout=5.0))
    return answer


def _remote_contacts(fleet: Fleet, armband: str) -> list[dict[str, Any]]:
    """The contacts the armband's engine holds, read from its own WebSocket ``state``."""
    with connect(fleet.nodes[armband].ws_url) as local:
        local.send(json.dumps({"type": "subscribe", "rate_hz": 50}))
        while True:
            message = json.loads(local.recv(timeout=5.0))
            if message["type"] == "state":
                return [c for c in message["contacts"] if not c["own"]]


def test_moves_reach_the_addressed_armband_and_the_latest_wins(fleet: Fleet) -> None:
    with connect(fleet.gateways[0].ws_url) as ws:
        welcome = _ask(ws, {"type": "hello", "id": 1})
        assert set(welcome["armbands"]) == set(fleet.nodes)
        down = {"type": "down", "armband": "a3", "contact": "hand", "x_cm": 1.9, "y_cm": 12.0}
        assert _ask(ws, {**down, "id": 2})["type"] == "ok"
        for step in range(60):
            y_cm = 12.0 - step * (9.6 / 59)
            ws.send(
                json.dumps(
                    {"type": "move", "armband": "a3", "contact": "hand", "x_cm": 1.9, "y_cm": y_cm}
                )
            )
        assert _ask(ws, {"type": "ping", "id": 3})["type"] == "pong"
        time.sleep(0.2)
        held = _remote_contacts(fleet, "a3")
        assert [c["contact"] for c in held] == ["hand"]
        # The last move (y = 2.4 cm) is where the contact is: nothing queued behind it.
        assert abs(held[0]["y_cm"] - 2.4) < 1e-6
        assert _remote_contacts(fleet, "a1") == []
        answer = _ask(
            ws, {"type": "move", "armband": "a1", "contact": "hand", "x_cm": 1, "y_cm": 1, "id": 4}
        )
        # The armband's node answers a move with an id (the gateway keeps no contact state).
        assert answer["type"] == "error"
        assert answer["message"].startswith("armband='a1': contact='hand' is not down")
    wait_until(lambda: _remote_contacts(fleet, "a3") == [], 30.0, "contact released on close")


def test_the_gateway_holds_each_connection_to_its_row_of_the_policy_table(fleet: Fleet) -> None:
    """A message over the ``fleet-gateway`` row's size (the gateway's server has the same
    frame limit, so it answers first) closes the connection 1009 naming the limit; a flood
    over the row's rate is answered ``rate_limited`` once, then closed 1008 when it
    is sustained; the welcome announces the row's deadline."""
    with connect(fleet.gateways[0].ws_url, max_size=None) as ws:
        assert _ask(ws, {"type": "hello", "id": 1})["watchdog_s"] == 2.0
        ws.send(json.dumps({"type": "ping", "pad": "x" * 70_000}))
        with pytest.raises(ConnectionClosed) as closed:
            ws.recv(timeout=10.0)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1009
        assert "limit of 65536 bytes" in closed.value.rcvd.reason
    with connect(fleet.gateways[0].ws_url) as ws:
        seen: list[dict[str, Any]] = []
        started_s = time.monotonic()
        with pytest.raises(ConnectionClosed) as closed:
            while time.monotonic() - started_s < 30.0:
                for _ in range(500):
                    ws.send('{"type": "ping"}')
                with contextlib.suppress(TimeoutError):
                    while True:
                        seen.append(json.loads(ws.recv(timeout=0)))
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
        assert [m["code"] for m in seen if m["type"] == "error"] == ["rate_limited"]


def test_a_contact_without_an_armband_is_refused_by_name(fleet: Fleet) -> None:
    with connect(fleet.gateways[1].ws_url) as ws:
        answer = _ask(ws, {"type": "down", "contact": "c", "x_cm": 1.0, "y_cm": 1.0, "id": 9})
        assert answer["type"] == "error"
        assert answer["message"].startswith("armband: field required")
        answer = _ask(
            ws,
            {"type": "down", "armband": "gone", "contact": "c", "x_cm": 1.0, "y_cm": 1.0, "id": 10},
        )
        assert answer["code"] == "not_found"
        assert "'gone'" in answer["message"]


def test_a_vanished_gateway_releases_its_contacts_on_every_armband(fleet: Fleet) -> None:
    gateway = Gateway(fleet.folder, fleet.cluster).start()
    try:
        ws = connect(gateway.ws_url, legacy=True)
        for armband in ("a1", "a2"):
            down = {"type": "down", "armband": armband, "contact": "c", "x_cm": 1.9, "y_cm": 7.2}
            assert _ask(ws, {**down, "id": armband})["type"] == "ok"
        assert len(_remote_contacts(fleet, "a1")) == len(_remote_contacts(fleet, "a2")) == 1
        with WakeUpLag() as lag:
            gateway.kill()
            killed_s = time.monotonic()
            for armband in ("a1", "a2"):
                wait_until(
                    lambda a=armband: _remote_contacts(fleet, a) == [], 60.0, f"{armband} released"
                )
            elapsed_s = time.monotonic() - killed_s
        # The node's fleet watchdog lets go after watchdog_s of silence, checked every quarter
        # (plus 2 s on a quiet machine, more as this one was late).
        assert elapsed_s < WATCHDOG_S * 1.25 + 2.0 + 10 * lag.worst_s, (elapsed_s, lag.worst_s)
        node = fleet.nodes["a1"]
        released = node.metric(
            "phantomtouch_fleet_messages_total", 'outcome="watchdog_release",subject="contact"'
        )
        assert released >= 1
        ws.close()
    finally:
        gateway.kill()


def test_a_client_is_told_when_an_armband_lets_go_of_its_contacts(fleet: Fleet) -> None:
    """A node's release reaches its client through the gateway, as the service's
    ``released`` with the armband: a stop of one armband, and the client's silence on the
    other (docs/fleet.md, "Live contacts")."""
    with connect(fleet.gateways[0].ws_url) as ws:
        for armband in ("a1", "a2"):
            down = {"type": "down", "armband": armband, "contact": "c", "x_cm": 1.9, "y_cm": 7.2}
            assert _ask(ws, {**down, "id": armband})["type"] == "ok"
        ws.send(json.dumps({"type": "stop", "armband": "a1", "id": "stop"}))
        released: list[dict[str, Any]] = []
        end_s = time.monotonic() + 10 * WATCHDOG_S + 10.0
        while len(released) < 2 and time.monotonic() < end_s:
            with contextlib.suppress(TimeoutError):
                message = json.loads(ws.recv(timeout=1.0))
                if message["type"] == "released":
                    released.append(message)
        assert sorted(released, key=lambda m: str(m["armband"])) == [
            {"type": "released", "armband": "a1", "reason": "stop", "contacts": ["c"]},
            {"type": "released", "armband": "a2", "reason": "watchdog", "contacts": ["c"]},
        ]
        assert _remote_contacts(fleet, "a1") == _remote_contacts(fleet, "a2") == []
