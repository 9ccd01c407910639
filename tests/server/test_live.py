"""The service as a client sees it: a real uvicorn on a loopback port.

Each test talks HTTP and WebSocket over 127.0.0.1 only; every loop is bounded in count
and in time.
"""

from __future__ import annotations

import asyncio
import json
import re
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from websockets.asyncio.client import ClientConnection, connect

from tests.support.live_server import LiveServer
from tests.support.service import LONG, STROKE
from tests.support.waiting import wait_until
from tests.support.yardstick import WakeUpLag


def metric(live: LiveServer, name: str) -> float:
    text = httpx.get(f"{live.url}/metrics").text
    match = re.search(rf"^{name} (\S+)$", text, re.MULTILINE)
    assert match, f"{name} not in /metrics"
    return float(match.group(1))


async def ask(ws: ClientConnection, message: dict[str, Any]) -> dict[str, Any]:
    await ws.send(json.dumps(message))
    return await receive(ws)


async def receive(ws: ClientConnection, timeout_s: float = 5.0) -> dict[str, Any]:
    answer: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), timeout_s))
    return answer


async def contacts_seen(observer: ClientConnection) -> list[str]:
    """Other connections' contacts in the observer's first state after now (server clock)."""
    await observer.send(json.dumps({"type": "ping", "id": "now"}))
    while (message := await receive(observer))["type"] != "pong":
        pass
    now_s = message["server_time_s"]
    while (message := await receive(observer))["type"] != "state" or (
        message["server_time_s"] < now_s
    ):
        pass
    return [c["contact"] for c in message["contacts"] if not c["own"]]


def test_rest_round_trip(live: LiveServer) -> None:
    with httpx.Client(base_url=live.url, timeout=10) as client:
        health = client.get("/health").json()
        assert (health["status"], health["backend"], health["engine"]) == ("ok", "null", "running")
        assert client.get("/device").json()["backend"] == "null"
        assert client.put("/patterns/live-stroke", json=STROKE).status_code == 200
        assert client.get("/patterns/live-stroke").json()["speed_cm_s"] == 5.0
        job = client.post("/patterns/live-stroke/play", json={"start_in_ms": 100}).json()
        assert client.get(f"/jobs/{job['job_id']}").json()["state"] == "scheduled"
        wait_until(
            lambda: client.get(f"/jobs/{job['job_id']}").json()["state"] == "playing",
            5.0,
            "the audio thread starts it",
        )
        assert client.delete(f"/jobs/{job['job_id']}").json()["state"] == "stopped"
        wav = client.post("/render", json={"preset": "vr/tap"})
        assert (wav.status_code, wav.headers["content-type"]) == (200, "audio/wav")
        refused = client.post("/touch", json={**STROKE, "fade_in_s": -1})
        assert refused.status_code == 422
        assert refused.json()["error"]["fields"][0]["field"] == "fade_in_s"
        assert client.delete("/patterns/live-stroke").status_code == 204


def test_contact_stream(live: LiveServer) -> None:
    async def scenario() -> None:
        async with connect(live.ws_url) as ws, connect(live.ws_url) as observer:
            assert (await ask(ws, {"type": "hello", "id": 0}))["type"] == "welcome"
            await ask(observer, {"type": "subscribe", "rate_hz": 30, "id": 1})
            await ask(ws, {"type": "down", "contact": "hand", "x_cm": 1.9, "y_cm": 12, "id": 1})
            for k in range(45):  # half a second of a 90 Hz hand stroking down the arm
                await ws.send(
                    json.dumps(
                        {"type": "move", "contact": "hand", "x_cm": 1.9, "y_cm": 12 - k * 0.2}
                    )
                )
                await asyncio.sleep(1 / 90)
            assert (await ask(ws, {"type": "ping", "id": 2}))["type"] == "pong"
            assert await contacts_seen(observer) == ["hand"]
            assert await ask(ws, {"type": "up", "contact": "hand", "id": 3}) == {
                "type": "ok",
                "id": 3,
            }
            assert await contacts_seen(observer) == []

    asyncio.run(scenario())


def test_vanished_clients_are_released(live: LiveServer) -> None:
    async def scenario() -> None:
        async with connect(live.ws_url) as observer:
            await ask(observer, {"type": "subscribe", "rate_hz": 20, "id": 1})
            silent = await connect(live.ws_url)
            await ask(silent, {"type": "down", "contact": "quiet", "x_cm": 1, "y_cm": 3, "id": 1})
            killed = await connect(live.ws_url)
            await ask(killed, {"type": "down", "contact": "gone", "x_cm": 3, "y_cm": 9, "id": 1})
            assert sorted(await contacts_seen(observer)) == ["gone", "quiet"]

            with WakeUpLag() as lag:  # 1 s, and 1 s past the watchdog's 2 s, when on time
                killed.transport.abort()  # the socket dies without a closing handshake
                started = time.monotonic()
                while "gone" in await contacts_seen(observer):
                    assert time.monotonic() - started < 30.0, "a dropped connection is released"
                dropped_s = time.monotonic() - started
                assert await contacts_seen(observer) == ["quiet"]

                started = time.monotonic()  # the silent client neither sends nor closes
                while await contacts_seen(observer):
                    assert time.monotonic() - started < 30.0, "the 2 s watchdog releases it"
                silent_s = time.monotonic() - started
            assert dropped_s < 1.0 + 10 * lag.worst_s, ("released at once", dropped_s, lag.worst_s)
            assert 1.0 < silent_s < 2.0 + 1.0 + 10 * lag.worst_s, (silent_s, lag.worst_s)
            assert await receive(silent) == {
                "type": "released",
                "reason": "watchdog",
                "contacts": ["quiet"],
            }
            await silent.close()

    asyncio.run(scenario())


def test_stop_under_load(live: LiveServer) -> None:
    """POST /stop while four clients hammer POST /touch: answered at once, everything off.

    Touches answered before the stop was sent must be stopped; those in flight while it
    ran may land on either side of it and are stopped one by one afterwards.
    """
    clients, per_client, budget_s = 4, 300, 120.0
    stop_sent = threading.Event()
    stop_done = threading.Event()
    before: list[str] = []
    in_flight: list[str] = []
    statuses: list[int] = []
    touch_s: list[float] = []
    lock = threading.Lock()

    def hammer() -> None:
        deadline = time.monotonic() + budget_s
        with httpx.Client(base_url=live.url, timeout=10) as client:
            for _ in range(per_client):
                if stop_done.is_set() or time.monotonic() > deadline:
                    return
                began = time.monotonic()
                answer = client.post("/touch", json=LONG)
                with lock:
                    touch_s.append(time.monotonic() - began)
                    statuses.append(answer.status_code)
                    if answer.status_code == 202:
                        job = answer.json()["job_id"]
                        (in_flight if stop_sent.is_set() else before).append(job)

    threads = [threading.Thread(target=hammer) for _ in range(clients)]
    for thread in threads:
        thread.start()
    wait_until(lambda: len(statuses) >= 100, budget_s / 2, "load is running")
    with httpx.Client(base_url=live.url, timeout=10) as client:
        stop_sent.set()
        started = time.monotonic()
        answer = client.post("/stop")
        stop_s = time.monotonic() - started
        stop_done.set()
    for thread in threads:
        thread.join(budget_s + 10)
    assert answer.status_code == 200
    assert set(statuses) <= {202, 429, 503}, "played, over this client's quota, or busy"
    # 1 s, and more as a plain POST /touch took longer in this run
    bound_s = 1.0 + 20 * float(np.median(touch_s))
    assert stop_s < bound_s, f"POST /stop took {stop_s:.3f} s under load, over {bound_s:.3f} s"
    with httpx.Client(base_url=live.url, timeout=10) as client:
        states = {client.get(f"/jobs/{job}").json()["state"] for job in before}
        assert states == {"stopped"}
        for job in in_flight:
            client.delete(f"/jobs/{job}")
    wait_until(lambda: metric(live, "phantomtouch_active_voices") == 0.0, 5.0, "silence")
    print(
        f"stop under load: {len(statuses)} touches, {len(before)} before the stop, "
        f"{len(in_flight)} in flight; POST /stop answered in {stop_s * 1e3:.1f} ms"
    )


def test_restart_after_kill_keeps_the_library(tmp_path: Path) -> None:
    db = tmp_path / "library.db"
    names = [f"stroke-{k}" for k in range(5)]
    server = LiveServer(db).start()
    try:
        for k, name in enumerate(names):
            body = {**STROKE, "speed_cm_s": 2.0 + k}
            assert httpx.put(f"{server.url}/patterns/{name}", json=body).status_code == 200
    finally:
        server.kill()  # SIGKILL right after the last answer: no shut-down runs
    assert server.process is not None and server.process.returncode == -9
    with LiveServer(db) as again:
        listed = httpx.get(f"{again.url}/patterns").json()
        assert [p["name"] for p in listed] == names
        assert [p["summary"]["speed_cm_s"] for p in listed] == [2.0, 3.0, 4.0, 5.0, 6.0]
        played = httpx.post(f"{again.url}/patterns/stroke-4/play")
        assert played.status_code == 202


def test_serve_picks_its_output_and_says_which(tmp_path: Path) -> None:
    with LiveServer(tmp_path / "patterns.db", output=None) as server:
        device = httpx.get(f"{server.url}/device").json()
        log = server.log()
    assert device["backend"] in ("sounddevice", "null")
    if device["backend"] == "null":
        assert "playing on the null output" in log
    else:
        assert f"playing on the sound card {device['output_device']!r}" in log


@pytest.mark.parametrize("path", ["/health", "/device", "/clock"])
def test_loopback_only(live: LiveServer, path: str) -> None:
    assert live.url.startswith("http://127.0.0.1:")
    assert httpx.get(f"{live.url}{path}").status_code == 200
