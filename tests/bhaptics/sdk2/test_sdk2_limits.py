"""SDK2 connections as owners, and bad input, against a real ``phantomtouch serve
--bhaptics ... --output capture:FILE.wav`` (raw clients: no bHaptics library needed).

- a paused play is silent, and listed as playing again once resumed;
- a workspace stored in the library (``PUT /bhaptics/workspaces/{id}``) is a connecting
  game's events, and plays where the mapping puts them;
- the emergency stop (``POST /stop``) silences a connection's plays and loops within the
  next block and the release, and nothing re-triggers after it; the active lists say so;
- a connection that closes mid-play leaves nothing on;
- a message that cannot be read (not JSON, a binary frame, wrong types, an unknown type,
  NaN, a deployment of 10,000 events) is answered with the active lists and the connection
  stays; one too large is closed 1009; a wrong path is refused 404; nothing stays on and
  the output never exceeds full scale.
"""

from __future__ import annotations

import asyncio
import json
import ssl
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from tests.bhaptics.sdk2.deployments import auth_init_game, deployment, game_events, mapping
from tests.bhaptics.sdk2.raw_client import RawClient, envelope
from tests.bhaptics.test_standin_live import RELEASE_S, SILENT, TRANSIT_S, Capture, place
from tests.support.clocks import ClockReads
from tests.support.live_server import HOST, LiveServer, free_ports

WORKSPACE = "limits"
STORED = "from-the-library"


def play(event: str, request_id: int, **extra: Any) -> str:
    return envelope(
        "SdkPlay", {"eventName": event, "requestId": request_id, "intensity": 1, **extra}
    )


async def scenario(base: str, server_url: str, marks: dict[str, Any]) -> None:
    stored = httpx.put(
        f"{server_url}/bhaptics/workspaces/{STORED}", json=game_events(STORED), timeout=10.0
    )
    assert stored.status_code == 200, stored.text
    async with RawClient(f"{base}?workspace_id={STORED}&api_key=k&version=0.0.4") as library:
        events = await library.expect("ServerEventList", 0.0)
        assert {e["eventName"]: e["eventTime"] for e in events}["buzz"] == 300
        marks["stored_buzz"] = await library.send(play("buzz", 1))
        await asyncio.sleep(0.6)
    url = f"{base}?workspace_id={WORKSPACE}&api_key=k&version=0.0.4"
    async with RawClient(url) as game, RawClient(url) as leaver:
        await game.expect("ServerEventNameList", 0.0)
        sent = await game.send(auth_init_game(WORKSPACE, game_events(WORKSPACE)))
        await game.expect("ServerEventList", sent, where=lambda events: len(events) == 5)

        # pause and resume: silent while paused, listed again once resumed (its one voice
        # began before the place it was paused at: it is not heard again, docs/bhaptics.md)
        await game.send(play("long", 21))
        await asyncio.sleep(0.5)
        marks["pause"] = await game.send(envelope("SdkPause", "long"))
        await game.expect("ServerActiveRequestIdList", marks["pause"], where=lambda ids: ids == [])
        await asyncio.sleep(0.5)
        marks["resume"] = await game.send(envelope("SdkResume", ""))
        await game.expect(
            "ServerActiveRequestIdList", marks["resume"], where=lambda ids: ids == [21]
        )
        await asyncio.sleep(0.5)
        marks["paused_stop"] = await game.send(envelope("SdkStopAll", ""))
        await game.expect(
            "ServerActiveRequestIdList", marks["paused_stop"], where=lambda ids: ids == []
        )
        await asyncio.sleep(0.3)

        # a loop of 50 and a long event; the emergency stop silences both for good
        loop = {"eventName": "stab", "requestId": 11, "interval": 100, "maxCount": 50}
        await game.send(envelope("SdkPlayLoop", loop))
        await game.send(play("long", 12))
        await game.expect("ServerActiveRequestIdList", sent, where=lambda ids: ids == [11, 12])
        await asyncio.sleep(0.6)
        marks["stop"] = time.monotonic()
        answer = httpx.post(f"{server_url}/stop", timeout=5.0)
        assert answer.status_code == 200, answer.text
        marks["stop_frame"] = answer.json()["frames"]
        await game.expect("ServerActiveRequestIdList", marks["stop"], where=lambda ids: ids == [])
        await asyncio.sleep(2.0)
        marks["stop_end"] = time.monotonic()

        # a connection that goes mid-play
        await leaver.expect("ServerEventNameList", 0.0)
        await leaver.send(play("long", 1))
        await leaver.send(envelope("SdkPlayLoop", {**loop, "requestId": 2}))
        await asyncio.sleep(0.5)
        marks["playing"] = time.monotonic()
        await leaver.close()
        marks["leave"] = time.monotonic()  # the server has the close
    async with RawClient(url) as bad:
        await asyncio.sleep(1.0)
        marks["bad"] = time.monotonic()
        refusals = [
            "not json",
            b"\x00\x01binary",
            json.dumps({"Type": "SdkExplode", "Message": ""}),
            json.dumps({"Type": 5, "Message": {}}),
            json.dumps({"Type": "SdkPlay", "Message": [1, 2]}),
            play("stab", 3, intensity=float("nan")),
            envelope("SdkPlay", {"eventName": ["stab"], "requestId": 4}),
            envelope(
                "SdkPlayDotMode",
                {"requestId": 5, "position": 1, "durationMillis": "x", "motorValues": [1]},
            ),
            envelope(
                "SdkRequestAuthInit",
                {
                    "authentication": "{}",
                    "haptic": json.dumps(
                        deployment(WORKSPACE, [mapping(f"e{k}") for k in range(10_000)])
                    ),
                },
            ),
        ]
        for text in refusals:
            sent = await bad.send(text)
            await bad.expect("ServerActiveRequestIdList", sent)
        # the refused deployment left the workspace's events as they were
        sent = await bad.send(envelope("SdkRequestAuth", {"ApplicationId": WORKSPACE}))
        events = await bad.expect("ServerEventList", sent)
        assert len(events) == 5
        # a wild but readable play: clamped, under the ceiling
        sent = await bad.send(play("stab", 6, intensity=1e9, duration=1e9))
        await bad.expect("ServerActiveRequestIdList", sent, where=lambda ids: ids == [6])
        await bad.send(envelope("SdkStopAll", ""))
        await asyncio.sleep(0.5)
        marks["end"] = time.monotonic()
        await bad.send("x" * (17 << 20))
        marks["huge_close"] = await bad.closed_with()


def test_stop_leave_and_bad_input_leave_nothing_on(tmp_path: Path) -> None:
    wav = tmp_path / "band.wav"
    sdk1_port, sdk2_port = free_ports(2)
    server = LiveServer(
        tmp_path / "library.db",
        output=f"capture:{wav}",
        args=("--bhaptics", f"{HOST}:{sdk1_port}", "--bhaptics-sdk2", f"{HOST}:{sdk2_port}"),
        env={"XDG_DATA_HOME": str(tmp_path / "data")},
    ).start()
    base = f"wss://{HOST}:{sdk2_port}/v3/feedback"
    marks: dict[str, Any] = {}
    try:
        device = httpx.get(f"{server.url}/device", timeout=5.0).json()
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE

        async def wrong_path() -> None:
            async with connect(f"wss://{HOST}:{sdk2_port}/v2/feedbacks", ssl=context):
                pass

        with ClockReads(server.url) as clocks:
            asyncio.run(scenario(base, server.url, marks))
            with pytest.raises(InvalidStatus) as refused:
                asyncio.run(wrong_path())
            assert refused.value.response.status_code == 404
            assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200
            marks["after"] = time.monotonic()
            time.sleep(1.0)
    finally:
        server.stop()
    assert "Traceback" not in server.log()
    band = Capture(wav, clocks, device)
    stop_s = band.block_s * 2 + RELEASE_S

    t = marks["stored_buzz"]
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 0.5, 1.0)) < 0.5

    t = marks["pause"]
    assert band.peak(t - 0.3, t - 0.05) > SILENT, "nothing played before the pause"
    assert band.peak(t + TRANSIT_S + stop_s, marks["resume"]) <= SILENT, "it played on while paused"

    t = marks["stop"]
    assert band.peak(t - 0.4, t - 0.05) > SILENT, "nothing played before the stop"
    silent_from = marks["stop_frame"] + round(stop_s * band.rate_hz)
    # a margin of 0.3 s before the next client plays
    after = band.samples[silent_from : band.end(marks["stop_end"] - 0.3)]
    assert np.max(np.abs(after)) <= SILENT, "a play or loop went on"
    t = marks["leave"]
    assert band.peak(t - 0.4, marks["playing"]) > SILENT, "nothing played before the close"
    assert band.peak(t + TRANSIT_S + stop_s, marks["bad"] - 0.3) <= SILENT, (
        "the closed connection's play went on"
    )
    assert band.peak(marks["bad"], marks["end"]) <= 1.0
    assert band.peak(marks["end"] - 0.3, marks["after"] + 1.0) <= SILENT
    assert marks["huge_close"][0] == 1009
