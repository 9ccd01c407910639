"""Where the stand-in let the wearer feel what they should not, each tried from outside: a real
``phantomtouch serve --bhaptics ... --output capture:FILE.wav`` process, games written from
the protocol study (:mod:`tests.bhaptics.player_client`, :mod:`tests.bhaptics.hung_game`),
and the band's signal read from the capture.

- the emergency stop sent while a key is being planned: nothing of the key is felt after it;
- a game frozen after its submit: its frame and key end one deadline after its last message;
- one message asking for 30,000 submits: it is refused, and another client's live contact on
  ``/ws`` is never let go of meanwhile;
- eight idle connections: a game that connects next is served (an idle one yields);
- eight connections registering 250,000 points each: the server's memory stays bounded and
  is given back after they close.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.asyncio.client import connect

from phantomtouch.service.admission.policy import BHAPTICS_DEADLINE_S
from tests.bhaptics.player_client import PlayerClient, crowd_project, frame_submits
from tests.bhaptics.test_standin_live import RELEASE_S, SILENT, Capture, dot_project
from tests.support.live_server import HOST, LiveServer, free_port

ROOT = Path(__file__).resolve().parents[2]
DEADLINE_S = BHAPTICS_DEADLINE_S
"""How long the stand-in keeps what a silent game plays (the admission's policy table)."""


class Standin:
    """A serve process with the stand-in and a capture; :meth:`band` after :meth:`stop`."""

    def __init__(self, tmp_path: Path, env: dict[str, str] | None = None) -> None:
        self.wav = tmp_path / "band.wav"
        self.port = free_port()
        self.server = LiveServer(
            tmp_path / "library.db",
            output=f"capture:{self.wav}",
            args=("--bhaptics", f"{HOST}:{self.port}"),
            env=env,
        ).start()
        self.ws_url = f"ws://{HOST}:{self.port}/v2/feedbacks"
        self.device = httpx.get(f"{self.server.url}/device", timeout=10.0).json()
        self.clocks: list[dict[str, Any]] = []
        self.read_clock()

    def read_clock(self) -> dict[str, Any]:
        """``GET /clock``: the engine's frame count at a server time; the capture places
        spans by every clock read (:mod:`tests.support.clocks`)."""
        clock: dict[str, Any] = httpx.get(f"{self.server.url}/clock", timeout=10.0).json()
        self.clocks.append(clock)
        return clock

    def stop(self) -> Capture:
        self.server.stop()
        return Capture(self.wav, self.clocks, self.device)

    @property
    def after_stop_s(self) -> float:
        """A stopped touch is silent this long after the stop: the next block, the release."""
        return 2 * self.device["block_frames"] / self.device["sample_rate_hz"] + RELEASE_S


async def stop_during_planning(standin: Standin, marks: dict[str, Any]) -> None:
    """A 200-voice, 8 s key submitted, the stop sent 0.1 s later while it is planned; then
    40 one-voice keys, each stopped 0-18 ms after its submit."""
    url = standin.server.url
    async with PlayerClient(standin.ws_url) as game, httpx.AsyncClient(timeout=30.0) as http:
        await game.send({"Register": [{"Key": "crowd", "Project": crowd_project(200, 8000, 40)}]})
        before = len(game.statuses)
        await game.ws.send(json.dumps({"Submit": [{"Type": "key", "Key": "crowd"}]}))
        await asyncio.sleep(0.1)
        marks["crowd_stop"] = (await http.post(f"{url}/stop")).json()
        await game.wait_statuses(before + 1, timeout_s=120.0)
        marks["crowd_answered"] = game.statuses[before][0]
        await asyncio.sleep(8.5)

        await game.send({"Register": [{"Key": "one", "Project": dot_project("ForearmR", 3, 600)}]})
        marks["one_stops"] = []
        for trial in range(40):
            await game.ws.send(json.dumps({"Submit": [{"Type": "key", "Key": "one"}]}))
            await asyncio.sleep(0.018 * trial / 39)
            stop = await http.post(f"{url}/stop")
            marks["one_stops"].append(stop.json())
            await asyncio.sleep(0.7)
        marks["end"] = time.monotonic()


def test_the_stop_voids_keys_being_planned(tmp_path: Path) -> None:
    """The wearer pressed stop while the game's key was still being planned: what they felt
    after the stop (before: a 200-voice key started after the stop and ran its whole 8 s;
    4 of 40 one-voice keys stopped 0-18 ms after their submit played on)."""
    standin = Standin(
        tmp_path,
        env={"PHANTOMTOUCH_MAX_VOICES": "256", "PHANTOMTOUCH_MAX_VOICES_PER_CLIENT": "256"},
    )
    marks: dict[str, Any] = {}
    try:
        asyncio.run(stop_during_planning(standin, marks))
    finally:
        band = standin.stop()
    after = standin.after_stop_s
    # each stop's answer is a clock too (its server time and frame): a span after a stop is
    # placed by it, so a stall of the engine earlier in the run cannot shift the span onto
    # the next trial's key
    crowd_stop = marks["crowd_stop"]
    stop = crowd_stop["server_time_s"]
    assert marks["crowd_answered"] > stop, (
        "the 200-voice key was planned before the stop arrived: the race was not reached"
    )
    felt = band.peak(stop + after, stop + 8.2, crowd_stop)
    assert felt <= SILENT, (
        f"the wearer felt the 200-voice key at {felt:.2f} FS after the emergency stop"
    )
    played_on = [
        k
        for k, answer in enumerate(marks["one_stops"])
        if band.peak(answer["server_time_s"] + after, answer["server_time_s"] + 0.65, answer)
        > SILENT
    ]
    assert not played_on, (
        f"the wearer felt {len(played_on)} of 40 one-voice keys after the emergency stop "
        f"(trials {played_on})"
    )


def test_a_hung_game_lets_go_one_deadline_after_its_last_message(tmp_path: Path) -> None:
    """A game froze (SIGSTOP) right after playing a 60 s frame and a 60 s key, its socket
    open: how long the wearer felt them (before: 30-100 s, the stand-in renewing them
    itself while they "played")."""
    standin = Standin(tmp_path)
    game = subprocess.Popen(
        [sys.executable, "-m", "tests.bhaptics.hung_game", standin.ws_url, "60000"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert game.stdout is not None
        line = game.stdout.readline()
        assert line.startswith("playing "), f"the game did not get to play: {line!r}"
        playing_s = float(line.split()[1])
        game.send_signal(signal.SIGSTOP)
        time.sleep(DEADLINE_S + 3.0)
        end_s = time.monotonic()
    finally:
        game.kill()
        game.wait()
        band = standin.stop()
    assert band.peak(playing_s, playing_s + 0.5) > SILENT, "nothing was felt before the hang"
    after = playing_s + DEADLINE_S + standin.after_stop_s + 0.1
    felt = band.peak(after, end_s)
    assert felt <= SILENT, (
        f"the wearer still felt {felt:.2f} FS from a game frozen {DEADLINE_S + 3.0:g} s ago "
        f"(deadline {DEADLINE_S:g} s)"
    )


async def huge_work_beside_a_contact(standin: Standin, marks: dict[str, Any]) -> None:
    """Another client holds a contact on ``/ws`` and moves it at 30 Hz while a game sends
    30,000 frame submits in one message, twice."""
    heavy = frame_submits(30_000)
    marks["bytes"] = len(heavy)
    released: list[Any] = []
    async with connect(standin.server.ws_url) as ws:
        await ws.send(json.dumps({"type": "down", "contact": "hand", "x_cm": 1.9, "y_cm": 7.2}))

        async def mover() -> None:
            k = 0
            while True:
                k += 1
                y_cm = 6.0 + (k % 20) * 0.1
                await ws.send(
                    json.dumps({"type": "move", "contact": "hand", "x_cm": 1.9, "y_cm": y_cm})
                )
                await asyncio.sleep(1 / 30)

        async def reader() -> None:
            async for text in ws:
                answer = json.loads(text)
                if answer.get("type") == "released":
                    released.append(answer)

        tasks = [asyncio.create_task(mover()), asyncio.create_task(reader())]
        await asyncio.sleep(1.0)
        marks["began"] = await asyncio.to_thread(standin.read_clock)
        marks["start"] = time.monotonic()
        async with PlayerClient(standin.ws_url) as game:
            for _ in range(2):
                await game.send(heavy, timeout_s=120.0)
            marks["answers"] = [status for _, status in game.statuses[1:]]
        await asyncio.sleep(1.0)
        marks["end"] = time.monotonic()
        marks["ended"] = await asyncio.to_thread(standin.read_clock)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    marks["released"] = released


def test_one_message_of_huge_work_holds_no_one_up(tmp_path: Path) -> None:
    """A game asked for 30,000 frames in one 10 MB message, twice, while another client's
    hand stroked the arm over ``/ws``: whether that hand's touch was let go of (before: the
    loop blocked ~4 s, the hand's contact was released by its watchdog and never came back)."""
    standin = Standin(tmp_path)
    marks: dict[str, Any] = {}
    try:
        asyncio.run(huge_work_beside_a_contact(standin, marks))
        metrics = httpx.get(f"{standin.server.url}/metrics", timeout=10.0).text
        health = httpx.get(f"{standin.server.url}/health", timeout=10.0)
    finally:
        band = standin.stop()
    assert marks["bytes"] > 10_000_000
    assert health.status_code == 200
    assert not marks["released"], (
        f"the other client's hand was let go of during the flood: {marks['released']}"
    )
    span = band.between(marks["start"], marks["end"], marks["began"], marks["ended"])
    envelope = np.max(np.abs(span), axis=1)
    blocks = envelope[: len(envelope) // 480 * 480].reshape(-1, 480).max(axis=1)
    assert blocks.min() > SILENT, "the hand's touch dropped out while the message was handled"
    assert 'phantomtouch_bhaptics_messages_total{outcome="refused"}' in metrics
    refused = [
        float(line.split()[-1])
        for line in metrics.splitlines()
        if line.startswith('phantomtouch_bhaptics_messages_total{outcome="refused"}')
    ]
    assert refused and refused[0] >= 2, "the over-large submits were not refused"


async def idle_crowd_then_a_game(standin: Standin, marks: dict[str, Any]) -> None:
    """Eight connections open and say nothing; then a game connects and plays a frame."""
    idle = [await connect(standin.ws_url, compression=None) for _ in range(8)]
    for ws in idle:
        await ws.recv()  # each got its status on connecting
    await asyncio.sleep(1.0)
    async with PlayerClient(standin.ws_url) as game:
        marks["frame"], status = await game.send(
            {
                "Submit": [
                    {
                        "Type": "frame",
                        "Key": "hello",
                        "Frame": {
                            "Position": "ForearmL",
                            "DotPoints": [{"Index": 2, "Intensity": 80}],
                            "PathPoints": [],
                            "DurationMillis": 500,
                        },
                    }
                ]
            }
        )
        marks["active"] = status["ActiveKeys"]
        await asyncio.sleep(0.7)
    closed = [ws.close_code for ws in idle if ws.close_code is not None]
    marks["yielded"] = closed
    for ws in idle:
        await ws.close()


def test_an_idle_crowd_yields_to_a_game(tmp_path: Path) -> None:
    """Eight idle connections held the stand-in's port when the game connected: whether the
    wearer felt the game's frame (before: the game was closed 1013 for as long as the idle
    ones stayed)."""
    standin = Standin(tmp_path)
    marks: dict[str, Any] = {}
    try:
        asyncio.run(idle_crowd_then_a_game(standin, marks))
    finally:
        band = standin.stop()
    assert "hello" in marks["active"]
    t = marks["frame"]
    assert band.peak(t + 0.1, t + 0.4) > SILENT, "the wearer felt nothing of the game's frame"
    assert marks["yielded"], "no idle connection yielded to the game"


def rss_mb(pid: int, field: str = "VmRSS") -> float:
    """The resident memory of process ``pid`` now (``VmRSS``) or at its highest so far
    (``VmHWM``), MB (Linux ``/proc``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no {field} for process {pid}")


def points_project(points: int) -> dict[str, Any]:
    """A Designer project of ``points`` dot points (one feedback of 20 ms per 20 points)."""
    feedback = [
        {
            "startTime": k * 20 % 500_000,
            "endTime": k * 20 % 500_000 + 20,
            "playbackType": "NONE",
            "pointList": [{"index": i, "intensity": 0.5} for i in range(20)],
        }
        for k in range(points // 20)
    ]
    mode = {
        "mode": "DOT_MODE",
        "dotMode": {"dotConnected": False, "feedback": feedback},
        "pathMode": {"feedback": []},
    }
    effect = {"startTime": 0, "offsetTime": 520_000, "modes": {"ForearmL": mode}}
    return {
        "layout": {"type": "Tactosy2", "layouts": {}},
        "tracks": [{"enable": True, "effects": [effect]}],
    }


async def eight_registrations(standin: Standin, pid: int, marks: dict[str, Any]) -> None:
    """One connection registers 250,000 points (three projects), then seven more do the
    same; then all close."""
    project = points_project(83_320)
    message = json.dumps({"Register": [{"Key": f"p{k}", "Project": project} for k in range(3)]})
    marks["before_mb"] = rss_mb(pid)
    games = [PlayerClient(standin.ws_url) for _ in range(8)]
    for game in games:
        await game.__aenter__()
    await games[0].send(message, timeout_s=120.0)
    marks["one_mb"] = rss_mb(pid, "VmHWM")
    for game in games[1:]:
        await game.send(message, timeout_s=120.0)
    marks["eight_mb"] = rss_mb(pid, "VmHWM")
    marks["registered"] = [len(g.statuses[-1][1]["RegisteredKeys"]) for g in games]
    for game in games:
        await game.__aexit__(None, None, None)
    # the server hands the memory back as it handles each close, in a worker thread: on a
    # loaded machine that can take a while, so read until one connection's cost is back or
    # 20 s have passed
    one_mb = marks["one_mb"] - marks["before_mb"]
    end_s = time.monotonic() + 20.0
    while True:
        await asyncio.sleep(0.5)
        marks["after_mb"] = rss_mb(pid)
        if marks["after_mb"] - marks["before_mb"] < one_mb or time.monotonic() > end_s:
            break


def test_registrations_cost_bounded_memory(tmp_path: Path) -> None:
    """Eight connections of one game's host registered 250,000 points each: the server's
    highest memory, against what one connection's registrations took, and what it gave back
    after they closed (before: eight connections cost +430 MB, most of it kept after
    close)."""
    standin = Standin(tmp_path)
    marks: dict[str, Any] = {}
    try:
        assert standin.server.process is not None
        asyncio.run(eight_registrations(standin, standin.server.process.pid, marks))
        health = httpx.get(f"{standin.server.url}/health", timeout=10.0)
    finally:
        standin.stop()
    assert health.status_code == 200
    one_mb = marks["one_mb"] - marks["before_mb"]
    eight_mb = marks["eight_mb"] - marks["before_mb"]
    kept_mb = marks["after_mb"] - marks["before_mb"]
    assert one_mb > 0, marks
    # The highest memory: reading a message costs memory for a moment (its JSON, its
    # projects), one message at a time, and only one connection's share is kept; eight
    # connections each holding a share came to 4.5 times one connection's cost.
    assert eight_mb < 3 * one_mb, (
        f"eight connections' registrations took {eight_mb:.0f} MB, one's {one_mb:.0f} MB ({marks})"
    )
    assert kept_mb < one_mb, (
        f"{kept_mb:.0f} MB stayed taken after the connections closed, more than one "
        f"connection's {one_mb:.0f} MB ({marks})"
    )
