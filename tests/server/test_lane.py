"""The contact lane of a real ``phantomtouch serve`` (``docs/lane.md``), from outside.

Each test starts the server as a subprocess on free loopback ports, talks to ``/ws`` with a
real WebSocket client and to the lane with a real UDP socket:

- a move over the lane lands where it says: recorded by ``--output capture:FILE.wav``, the
  channels after it carry the phantom gains of the new place (``gains_at``, the renderer's
  own law) and the old place falls silent;
- refusals name the field, the server stays up;
- a lane move renews its own connection's deadline, and no other;
- a closed connection's key is refused and its contacts are released;
- the lane counts in the connection's message rate.
"""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import soundfile
from websockets.sync.client import ClientConnection, connect

from phantomtouch import DeviceProfile, gains_at
from tests.support.live_server import HOST, LiveServer

DEVICE = DeviceProfile.default()
NEAR = DEVICE.actuators[0]
FAR = max(DEVICE.actuators, key=lambda a: np.hypot(a.x_cm - NEAR.x_cm, a.y_cm - NEAR.y_cm))
ANSWER_TIMEOUT_S = 10.0


class Client:
    """One ``/ws`` connection, said ``hello`` to, with a UDP socket for its lane."""

    def __init__(self, server: LiveServer) -> None:
        self.ws: ClientConnection = connect(server.ws_url, open_timeout=ANSWER_TIMEOUT_S)
        self.said = 0
        self.ws.send(json.dumps({"type": "hello", "client": "test_lane"}))
        self.welcome = self.receive("welcome")
        self.lane = self.welcome["lane"]
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.settimeout(ANSWER_TIMEOUT_S)

    def receive(self, kind: str) -> dict[str, Any]:
        """The next message of type ``kind`` (others, such as ``ok``, are passed over)."""
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while time.monotonic() < deadline:
            message = json.loads(self.ws.recv(timeout=ANSWER_TIMEOUT_S))
            if message["type"] == kind:
                return message
        raise AssertionError(f"no {kind} within {ANSWER_TIMEOUT_S} s")

    def say(self, message: dict[str, Any]) -> dict[str, Any]:
        """Send over ``/ws`` with an ``id`` and return its answer (``ok`` or ``error``)."""
        self.said += 1
        self.ws.send(json.dumps({**message, "id": self.said}))
        while True:
            answer = json.loads(self.ws.recv(timeout=ANSWER_TIMEOUT_S))
            if answer["type"] in ("ok", "error") and answer.get("id") == self.said:
                return answer

    def send_lane(self, datagram: bytes | dict[str, Any]) -> None:
        data = datagram if isinstance(datagram, bytes) else json.dumps(datagram).encode()
        self.udp.sendto(data, (HOST, self.lane["port"]))

    def lane_answer(self) -> dict[str, Any]:
        data, _ = self.udp.recvfrom(4096)
        answer: dict[str, Any] = json.loads(data)
        return answer

    def move(self, x_cm: float, y_cm: float, message_id: int | None = None) -> dict[str, Any]:
        move = {"type": "move", "contact": "hand", "x_cm": x_cm, "y_cm": y_cm}
        return {
            **move,
            "key": self.lane["key"],
            **({} if message_id is None else {"id": message_id}),
        }

    def close(self) -> None:
        self.udp.close()
        self.ws.close()


@pytest.fixture
def server(tmp_path: Path) -> Iterator[LiveServer]:
    with LiveServer(tmp_path / "p.db", env={"PHANTOMTOUCH_WATCHDOG_S": "0.5"}) as live:
        yield live


def test_a_lane_move_lands_on_its_place_in_the_captured_output(tmp_path: Path) -> None:
    wav = tmp_path / "out.wav"
    server = LiveServer(tmp_path / "p.db", output=f"capture:{wav}").start()
    try:
        client = Client(server)
        down = {"type": "down", "contact": "hand", "x_cm": NEAR.x_cm, "y_cm": NEAR.y_cm}
        assert client.say({**down, "intensity": 0.5})["type"] == "ok"
        time.sleep(0.3)
        client.send_lane(client.move(FAR.x_cm, FAR.y_cm, message_id=7))
        assert client.lane_answer() == {"type": "ok", "id": 7}
        time.sleep(0.3)
        assert client.say({"type": "up", "contact": "hand"})["type"] == "ok"
        client.close()
    finally:
        server.stop()  # SIGTERM: the engine closes and writes the WAV
    samples, _ = soundfile.read(wav, dtype="float64", always_2d=True)
    loud = np.abs(samples) > 1e-3
    near, far = NEAR.channel - 1, FAR.channel - 1
    assert loud[:, near].any() and loud[:, far].any()
    first_far = int(np.argmax(loud[:, far]))
    assert int(np.argmax(loud[:, near])) < first_far, "down at the near actuator, then the move"
    # 50 ms after the move began: the gains have ramped (one block) and the contact rests.
    start = first_far + DEVICE.sample_rate_hz // 20
    rest = samples[start : start + DEVICE.sample_rate_hz // 10]
    rms = np.sqrt(np.mean(rest**2, axis=0))
    expected = gains_at(DEVICE, FAR.x_cm, FAR.y_cm)
    # The output stage is linear below its limiter, so RMS per channel follows the gains;
    # 1e-6 of the loudest covers float32 rounding and the DC blocker's start.
    np.testing.assert_allclose(rms / rms.max(), expected / expected.max(), atol=1e-6)


def test_refusals_name_the_field_and_the_server_stays_up(server: LiveServer) -> None:
    client = Client(server)
    try:
        down = {"type": "down", "contact": "hand", "x_cm": NEAR.x_cm, "y_cm": NEAR.y_cm}
        assert client.say(down)["type"] == "ok"
        cases: list[tuple[bytes | dict[str, Any], str]] = [
            ({**client.move(0.0, 5000.0), "id": 1}, "y_cm"),
            ({**client.move(0.0, 0.0), "key": "not-a-key", "id": 2}, "key"),
            ({k: v for k, v in client.move(0.0, 0.0).items() if k != "key"}, "key"),
            ({**client.move(0.0, 0.0), "contact": "other", "id": 3}, "contact"),
            ({**client.move(0.0, 0.0), "type": "down"}, "type"),
            ({**client.move(0.0, 0.0), "intensity": 2.0}, "intensity"),
            (b"not json", "body"),
            (b"{" + b" " * 2000 + b"}", "body"),
        ]
        for datagram, field in cases:
            client.send_lane(datagram)
            answer = client.lane_answer()
            assert answer["type"] == "error", (datagram, answer)
            assert [f["field"] for f in answer["fields"]] == [field], (datagram, answer)
            assert answer["message"]
        client.send_lane(client.move(NEAR.x_cm, 3.0, message_id=4))
        assert client.lane_answer() == {"type": "ok", "id": 4}
        assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200
    finally:
        client.close()


def test_a_lane_move_renews_its_own_connection_only(server: LiveServer) -> None:
    mover, silent = Client(server), Client(server)
    try:
        for client in (mover, silent):
            down = {"type": "down", "contact": "hand", "x_cm": NEAR.x_cm, "y_cm": NEAR.y_cm}
            assert client.say(down)["type"] == "ok"
        deadline = time.monotonic() + 1.5  # three watchdogs of 0.5 s
        while time.monotonic() < deadline:
            mover.send_lane(mover.move(NEAR.x_cm, NEAR.y_cm))
            time.sleep(0.05)
        released = silent.receive("released")
        assert released["reason"] == "watchdog" and released["contacts"] == ["hand"]
        mover.send_lane(mover.move(FAR.x_cm, FAR.y_cm, message_id=9))
        assert mover.lane_answer() == {"type": "ok", "id": 9}, "its contact is still down"
    finally:
        mover.close()
        silent.close()


def test_a_closed_connection_releases_and_its_key_is_refused(server: LiveServer) -> None:
    leaving, observer = Client(server), Client(server)
    try:
        down = {"type": "down", "contact": "hand", "x_cm": NEAR.x_cm, "y_cm": NEAR.y_cm}
        assert leaving.say(down)["type"] == "ok"
        assert observer.say({"type": "subscribe", "rate_hz": 50})["type"] == "ok"
        assert [c["contact"] for c in observer.receive("state")["contacts"]] == ["hand"]
        key = leaving.lane["key"]
        leaving.ws.close()
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while observer.receive("state")["contacts"]:
            assert time.monotonic() < deadline, "the closed connection's contact stays down"
        leaving.send_lane({**leaving.move(FAR.x_cm, FAR.y_cm), "key": key, "id": 5})
        answer = leaving.lane_answer()
        assert answer["type"] == "error" and answer["fields"][0]["field"] == "key"
        assert not observer.receive("state")["contacts"], "a stale key puts nothing down"
    finally:
        leaving.close()
        observer.close()


def test_the_lane_counts_in_the_connections_message_rate(tmp_path: Path) -> None:
    env = {"PHANTOMTOUCH_WS_MESSAGES_PER_S": "20"}
    with LiveServer(tmp_path / "p.db", env=env) as server:
        client = Client(server)
        try:
            down = {"type": "down", "contact": "hand", "x_cm": NEAR.x_cm, "y_cm": NEAR.y_cm}
            assert client.say(down)["type"] == "ok"
            for _ in range(200):  # ten times the bucket: most are over the rate
                client.send_lane(client.move(NEAR.x_cm, 1.0))
            answer = client.lane_answer()
            assert answer["type"] == "error" and answer["code"] == "rate_limited", answer
        finally:
            client.close()
