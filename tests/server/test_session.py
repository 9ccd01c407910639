"""The WebSocket session (/ws) in-process, with the engine's audio thread running."""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketTestSession
from starlette.websockets import WebSocketDisconnect

from phantomtouch.server import create_app
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_UNSUPPORTED_DATA,
)
from tests.support.service import LONG, make_settings
from tests.support.waiting import wait_until
from tests.support.yardstick import WakeUpLag

TOKEN = "s3cret-token-0123456789"


def contacts(client: TestClient) -> list[dict[str, Any]]:
    engine = client.app.state.service.engine  # type: ignore[attr-defined]
    return list(engine.status().active_contacts)


def ask(ws: WebSocketTestSession, message: dict[str, Any]) -> dict[str, Any]:
    ws.send_json(message)
    answer: dict[str, Any] = ws.receive_json()
    return answer


@pytest.fixture
def app_client(tmp_path: Path) -> Callable[..., TestClient]:
    def build(**changes: Any) -> TestClient:
        return TestClient(create_app(make_settings(tmp_path, **changes)))

    return build


def test_hello_welcome(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        welcome = ask(ws, {"type": "hello", "client": "test", "protocol": 1, "id": "h"})
    assert welcome["type"] == "welcome"
    assert (welcome["protocol"], welcome["watchdog_s"], welcome["id"]) == (1, 2.0, "h")
    assert welcome["device"]["channels"] == 8
    assert welcome["device"]["actuators"][4] == {"x_cm": 3.8, "y_cm": 0.0, "channel": 5}


def test_contact_stream_down_move_up(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        assert ask(ws, {"type": "down", "contact": "L", "x_cm": 1.0, "y_cm": 2.0, "id": 1}) == {
            "type": "ok",
            "id": 1,
        }
        for k in range(50):
            ws.send_json({"type": "move", "contact": "L", "x_cm": 1.9, "y_cm": 2.0 + k * 0.1})
        assert ask(ws, {"type": "ping", "id": 2})["type"] == "pong"
        (held,) = contacts(client)
        assert (held["contact"], held["x_cm"], held["y_cm"]) == ("L", 1.9, pytest.approx(6.9))
        assert ask(ws, {"type": "up", "contact": "L", "id": 3}) == {"type": "ok", "id": 3}
        assert contacts(client) == []


def test_illegal_steps_and_malformed_frames_keep_the_session(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        not_down = ask(ws, {"type": "move", "contact": "R", "x_cm": 1, "y_cm": 1, "id": 7})
        assert (not_down["type"], not_down["code"], not_down["id"]) == ("error", "invalid", 7)
        assert "expected down, got move" in not_down["message"]
        ask(ws, {"type": "down", "contact": "R", "x_cm": 1, "y_cm": 1, "id": 8})
        twice = ask(ws, {"type": "down", "contact": "R", "x_cm": 1, "y_cm": 1})
        assert "expected move or up, got down" in twice["message"]
        ws.send_text("{not json")
        assert ws.receive_json()["code"] == "invalid_json"
        assert ask(ws, {"type": "dance", "id": "d"})["code"] == "unknown_type"
        bad = ask(ws, {"type": "move", "contact": "R", "x_cm": 5000, "y_cm": 1, "id": 9})
        assert bad["fields"][0]["field"] == "x_cm"
        assert "less than or equal to 1000" in bad["message"]
        assert ask(ws, {"type": "ping"})["type"] == "pong"


def test_watchdog_releases_a_silent_client(app_client: Callable[..., TestClient]) -> None:
    with app_client(watchdog_s=0.2) as client, client.websocket_connect("/ws") as ws:
        ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 1})
        started = time.monotonic()
        released = ws.receive_json()
        assert time.monotonic() - started >= 0.15
        assert released == {"type": "released", "reason": "watchdog", "contacts": ["L"]}
        assert contacts(client) == []
        engine = client.app.state.service.engine  # type: ignore[attr-defined]
        wait_until(lambda: max(engine.status().levels) == 0.0, 5.0, "silent after release")
        late = ask(ws, {"type": "move", "contact": "L", "x_cm": 1, "y_cm": 1, "id": 2})
        assert "released by up, the watchdog or stop" in late["message"]


def test_pings_keep_contacts_alive(app_client: Callable[..., TestClient]) -> None:
    """Pings a third of the watchdog apart keep a contact for over twice the watchdog. The
    watchdog is 0.3 s on a quiet machine, and grows by ten times how late a thread of the
    test was woken just before, so that a ping that is late on a busy one is still in time."""
    with WakeUpLag() as lag:
        time.sleep(0.2)
    watchdog_s = 0.3 + 10 * lag.worst_s
    with app_client(watchdog_s=watchdog_s) as client, client.websocket_connect("/ws") as ws:
        ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 1})
        for _ in range(8):
            time.sleep(watchdog_s / 3)
            assert ask(ws, {"type": "ping"})["type"] == "pong"
        assert [c["contact"] for c in contacts(client)] == ["L"]


def test_disconnect_releases_at_once(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 1})
        ask(ws, {"type": "down", "contact": "R", "x_cm": 0.5, "y_cm": 3.0, "id": 2})
        assert len(contacts(client)) == 2
    wait_until(lambda: contacts(client) == [], 5.0, "no contact left")


def test_global_stop_tells_each_connection(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 1})
        assert client.post("/stop").status_code == 200
        assert ws.receive_json() == {"type": "released", "reason": "stop", "contacts": ["L"]}
        again = ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 2})
        assert again == {"type": "ok", "id": 2}


def test_play_and_stop_a_job(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        played = ask(ws, {"type": "play", "id": "p", **LONG})
        assert (played["type"], played["id"]) == ("ok", "p")
        job_id = played["result"]["job_id"]
        assert played["result"]["duration_s"] == pytest.approx(30.0)
        assert ask(ws, {"type": "stop", "job_id": job_id, "id": "s"}) == {"type": "ok", "id": "s"}
        assert client.get(f"/jobs/{job_id}").json()["state"] == "stopped"
        unknown = ask(ws, {"type": "stop", "job_id": "feed", "id": "u"})
        assert (unknown["code"], unknown["id"], unknown["fields"][0]["field"]) == (
            "not_found",
            "u",
            "job_id",
        )
        missing = ask(ws, {"type": "play", "preset": "nope", "id": "n"})
        assert (missing["code"], missing["fields"][0]["field"]) == ("not_found", "preset")


def test_subscribe_streams_state(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 1})
        assert ask(ws, {"type": "subscribe", "rate_hz": 60, "id": 2}) == {"type": "ok", "id": 2}
        states = [ws.receive_json() for _ in range(3)]
        assert {s["type"] for s in states} == {"state"}
        state = states[-1]
        assert len(state["levels"]) == 8
        assert state["contacts"] == [{"contact": "L", "x_cm": 1.9, "y_cm": 7.2, "own": True}]
        assert state["active_voices"] >= 1
        assert {"underruns", "output_latency_s", "server_time_s"} <= set(state)
        ws.send_json({"type": "subscribe", "rate_hz": 0, "id": 3})
        while (message := ws.receive_json())["type"] == "state":
            pass
        assert message == {"type": "ok", "id": 3}


def _closed_with(ws: WebSocketTestSession) -> int:
    with pytest.raises(WebSocketDisconnect) as info:
        while True:
            ws.receive_json()
    return info.value.code


def test_binary_frame_closes_1003(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        ws.send_bytes(b"\x00\x01")
        assert _closed_with(ws) == WS_CLOSE_UNSUPPORTED_DATA


def test_message_over_the_limit_closes_1009(app_client: Callable[..., TestClient]) -> None:
    with app_client(max_ws_message_bytes=1024) as client, client.websocket_connect("/ws") as ws:
        ask(ws, {"type": "down", "contact": "L", "x_cm": 1.9, "y_cm": 7.2, "id": 1})
        ws.send_text('{"type": "ping", "pad": "' + "x" * 2000 + '"}')
        assert _closed_with(ws) == WS_CLOSE_MESSAGE_TOO_BIG
        wait_until(lambda: contacts(client) == [], 5.0, "no contact left")


def test_a_flood_is_answered_once_then_closed_1008(app_client: Callable[..., TestClient]) -> None:
    """Over the rate: the first dropped message is answered, the rest only counted; a
    flood that goes on for a second closes the connection."""
    with app_client(ws_messages_per_s=10) as client, client.websocket_connect("/ws") as ws:
        sent_s: list[float] = []
        started_s = time.monotonic()
        deadline = started_s + 1.6  # 5 ms apart: the bucket admits about one in 20
        while time.monotonic() < deadline:
            ws.send_json({"type": "ping", "id": len(sent_s)})
            sent_s.append(time.monotonic() - started_s)
            time.sleep(0.005 if len(sent_s) > 30 else 0.0)  # a burst of 30, then 200 per second
        answers: list[dict[str, Any]] = []
        with pytest.raises(WebSocketDisconnect) as closed:
            while True:
                answers.append(ws.receive_json())
        closed_s = time.monotonic() - started_s
        metrics = client.get("/metrics").text
    assert closed.value.code == WS_CLOSE_POLICY_VIOLATION
    assert "for 1 s" in closed.value.reason
    refused = [a for a in answers if a["type"] != "pong"]
    assert [a["code"] for a in refused] == ["rate_limited"], "only the first drop is answered"
    assert "more than 10 messages per second" in refused[0]["message"]
    pongs = len(answers) - 1
    # The burst, then what the bucket admits until the close: 1.6 s on time, longer on a
    # busy machine where the server reads the messages later than they were sent.
    assert 10 <= pongs <= 10 + 10 * closed_s + 1, "the burst, then what the bucket admits"
    match = re.search(r"^phantomtouch_ws_dropped_messages_total (\S+)$", metrics, re.MULTILINE)
    assert match is not None
    reason = re.search(r"; (\d+) messages dropped", closed.value.reason)
    assert reason is not None
    # A second of drops, counted: at least half of what was sent in the first second past
    # the bucket's ten (about 200 on time; fewer where the sender's sleeps overran).
    first_second = sum(1 for t_s in sent_s if t_s < 1.0) - 10
    assert float(match.group(1)) == int(reason.group(1)) >= first_second / 2, first_second
    assert "phantomtouch_ws_flood_closes_total 1.0" in metrics


def test_contacts_past_the_quota_are_refused_naming_it(
    app_client: Callable[..., TestClient],
) -> None:
    with (
        app_client(max_contacts_per_connection=2) as client,
        client.websocket_connect("/ws") as ws,
    ):
        for k, contact in enumerate(("a", "b")):
            down = {"type": "down", "contact": contact, "x_cm": 1.9, "y_cm": 3 + k, "id": k}
            assert ask(ws, down) == {"type": "ok", "id": k}
        refused = ask(ws, {"type": "down", "contact": "c", "x_cm": 1.9, "y_cm": 9, "id": 2})
        assert refused["code"] == "quota"
        assert "max_contacts_per_connection=2" in refused["message"]
        assert refused["fields"][0]["field"] == "contact"
        assert ask(ws, {"type": "up", "contact": "a", "id": 3})["type"] == "ok"
        assert ask(ws, {"type": "down", "contact": "c", "x_cm": 1.9, "y_cm": 9, "id": 4}) == {
            "type": "ok",
            "id": 4,
        }


def test_a_frame_nested_too_deeply_is_answered_and_the_session_kept(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        ws.send_text("[" * 30_000)
        refused = ws.receive_json()
        assert refused["code"] == "invalid_json"
        assert "nested too deeply" in refused["message"]
        assert ask(ws, {"type": "ping", "id": 1})["type"] == "pong"


def test_token_required(app_client: Callable[..., TestClient]) -> None:
    with app_client(token=TOKEN) as client:
        with client.websocket_connect("/ws") as ws:
            assert _closed_with(ws) == WS_CLOSE_POLICY_VIOLATION
        with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
            assert ask(ws, {"type": "hello"})["type"] == "welcome"
        with client.websocket_connect("/ws", headers={"Authorization": f"Bearer {TOKEN}"}) as ws:
            assert ask(ws, {"type": "ping"})["type"] == "pong"
