"""SDK2 "v4" (tact-js 2.x) end to end: a node client (``v4_client.mjs relay``, our own
implementation of the envelope) drives a real ``phantomtouch serve --bhaptics ...
--output capture:FILE.wav`` over ``ws://HOST:PORT/v4/feedback``.

- the envelope opens (a 2048-bit server key), a game's init defines its workspace, whose
  events a v3 connection of the same workspace then sees (one shared table);
- a played event is felt where the mapping puts it;
- the emergency stop (``POST /stop``) silences a loop and a long play for good;
- a connection that closes mid-play leaves nothing on;
- a step out of order closes 1008, data that does not decrypt 1007; the server stays up.
"""

from __future__ import annotations

import asyncio
import json
import os
import queue
import shutil
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tests.bhaptics.sdk2.deployments import auth_init_game, game_events
from tests.bhaptics.sdk2.raw_client import RawClient, envelope
from tests.bhaptics.test_standin_live import RELEASE_S, SILENT, TRANSIT_S, Capture, place
from tests.support.clocks import ClockReads
from tests.support.live_server import HOST, LiveServer, free_ports

CLIENT = Path(__file__).with_name("v4_client.mjs")
WORKSPACE = "web-game"
WAIT_S = 10.0


def node_program() -> str:
    program = shutil.which("node")
    if program is None:
        reason = "node is missing: scripts/install --dev installs the Debian package nodejs"
        if os.environ.get("CI") == "true":
            pytest.fail(f"{reason} (CI=true: the v4 test must run)")
        pytest.skip(reason)
    return program


class NodeGame:
    """One node client over a real connection; what it says is read in a thread."""

    def __init__(self, url: str) -> None:
        self.process = subprocess.Popen(
            [
                node_program(),
                "--experimental-websocket",
                "--no-warnings",
                str(CLIENT),
                "relay",
                url,
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.events: queue.Queue[dict[str, Any]] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.events.put(json.loads(line))

    def order(self, **order: Any) -> float:
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps(order) + "\n")
        self.process.stdin.flush()
        return time.monotonic()

    def next(self) -> dict[str, Any]:
        try:
            return self.events.get(timeout=WAIT_S)
        except queue.Empty:
            stderr = self.process.stderr.read() if self.process.poll() is not None else ""
            raise AssertionError(f"the node client said nothing for {WAIT_S} s {stderr}") from None

    def expect(self, kind: str, where: Any = lambda message: True) -> Any:
        """The first message of type ``kind`` that ``where`` accepts (its ``Message``)."""
        while True:
            event = self.next()
            assert "message" in event, f"expected {kind}, got {event}"
            document = json.loads(event["message"])
            body = json.loads(document["Message"]) if document["Message"] else ""
            if document["Type"] == kind and where(body):
                return body

    def closed(self) -> int:
        while True:
            event = self.next()
            if "closed" in event:
                self.process.wait(WAIT_S)
                return int(event["closed"])

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(WAIT_S)


def play(event: str, request_id: int, **extra: Any) -> str:
    return envelope(
        "SdkPlay", {"eventName": event, "requestId": request_id, "intensity": 1, **extra}
    )


async def v3_events(url: str) -> dict[str, int]:
    async with RawClient(url) as client:
        events = await client.expect("ServerEventList", 0.0)
        return {e["eventName"]: e["eventTime"] for e in events}


def scenario(base: str, server_url: str, v3_url: str, marks: dict[str, Any]) -> None:
    game = NodeGame(f"{base}?workspace_id={WORKSPACE}&api_key=k&version=2.0.0")
    try:
        assert game.next() == {"keyed": 2048}
        game.expect("ServerReady")
        game.order(send=auth_init_game(WORKSPACE, game_events(WORKSPACE)))
        game.expect("ServerEventList", lambda events: len(events) == 5)
        marks["v3_events"] = asyncio.run(v3_events(f"{v3_url}?workspace_id={WORKSPACE}"))

        marks["buzz"] = game.order(send=play("buzz", 1))
        game.expect("ServerActiveRequestIdList", lambda ids: ids == [1])
        time.sleep(0.6)

        loop = {"eventName": "stab", "requestId": 11, "interval": 100, "maxCount": 50}
        game.order(send=envelope("SdkPlayLoop", loop))
        game.order(send=play("long", 12))
        game.expect("ServerActiveRequestIdList", lambda ids: ids == [11, 12])
        time.sleep(0.6)
        marks["stop"] = time.monotonic()
        answer = httpx.post(f"{server_url}/stop", timeout=5.0)
        assert answer.status_code == 200, answer.text
        marks["stop_frame"] = answer.json()["frames"]
        game.expect("ServerActiveRequestIdList", lambda ids: ids == [])
        time.sleep(2.0)
        marks["stop_end"] = time.monotonic()

        game.order(send=play("long", 21))
        game.expect("ServerActiveRequestIdList", lambda ids: ids == [21])
        time.sleep(0.5)
        marks["playing"] = time.monotonic()
        game.order(close=True)
        assert game.closed() == 1000
        marks["leave"] = time.monotonic()
    finally:
        game.stop()
    time.sleep(1.0)

    out_of_order = NodeGame(f"{base}?workspace_id={WORKSPACE}")
    try:
        assert "keyed" in out_of_order.next()
        out_of_order.order(raw=json.dumps({"Type": "SdkClientKey", "Key": "AAAA"}))
        marks["out_of_order"] = out_of_order.closed()
    finally:
        out_of_order.stop()
    garbled = NodeGame(f"{base}?workspace_id={WORKSPACE}")
    try:
        assert "keyed" in garbled.next()
        garbled.expect("ServerReady")
        garbled.order(raw=json.dumps({"Type": "SdkData", "Key": None, "Data": "AAAA" * 10}))
        marks["garbled"] = garbled.closed()
    finally:
        garbled.stop()
    marks["end"] = time.monotonic()


@pytest.mark.parametrize("path", ["/v4/feedback", "/v4/feedback/"])
def test_a_web_game_plays_is_stopped_and_leaves_nothing_on(tmp_path: Path, path: str) -> None:
    wav = tmp_path / "band.wav"
    sdk1_port, sdk2_port = free_ports(2)
    server = LiveServer(
        tmp_path / "library.db",
        output=f"capture:{wav}",
        args=("--bhaptics", f"{HOST}:{sdk1_port}", "--bhaptics-sdk2", f"{HOST}:{sdk2_port}"),
        env={"XDG_DATA_HOME": str(tmp_path / "data")},
    ).start()
    marks: dict[str, Any] = {}
    try:
        device = httpx.get(f"{server.url}/device", timeout=5.0).json()
        with ClockReads(server.url) as clocks:
            scenario(
                f"ws://{HOST}:{sdk1_port}{path}",
                server.url,
                f"wss://{HOST}:{sdk2_port}/v3/feedback",
                marks,
            )
            assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200
            marks["after"] = time.monotonic()
            time.sleep(1.0)
    finally:
        server.stop()
    assert "Traceback" not in server.log()
    assert set(marks["v3_events"]) == {"stab", "buzz", "mixed", "long", "vest"}
    assert marks["out_of_order"] == 1008
    assert marks["garbled"] == 1007
    band = Capture(wav, clocks, device)
    stop_s = band.block_s * 2 + RELEASE_S

    t = marks["buzz"]
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 0.5, 1.0)) < 0.5

    t = marks["stop"]
    assert band.peak(t - 0.4, t - 0.05) > SILENT, "nothing played before the stop"
    silent_from = marks["stop_frame"] + round(stop_s * band.rate_hz)
    after = band.samples[silent_from : band.end(marks["stop_end"] - 0.3)]
    assert np.max(np.abs(after)) <= SILENT, "a play or loop went on after the stop"

    t = marks["leave"]
    assert band.peak(t - 0.4, marks["playing"]) > SILENT, "nothing played before the close"
    assert band.peak(t + TRANSIT_S + stop_s, marks["after"] + 1.0) <= SILENT, (
        "the closed play went on"
    )
    assert band.peak(0.0, marks["after"] + 1.0) <= 1.0
