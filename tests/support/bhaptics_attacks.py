"""Attacks on the bHaptics stand-in (docs/bhaptics.md, docs/security.md), against a live
server started with ``--bhaptics``, loopback only; each bounded in count and time, each
may run in a process of its own (:func:`tests.support.abuse.in_process`), and each returns
what it saw for ``benchmarks/bench_abuse.py`` to print:

- :func:`huge_message`: 30,000 frame submits in one message (10.7 MB), twice, while another
  client's ``/ws`` contact moves at 30 Hz;
- :func:`idle_crowd`: eight idle connections, then a game plays a frame;
- :func:`stop_while_planning`: a 200-voice key, the stop sent 0.1 s after its submit;
- :func:`hung_game`: a game frozen (SIGSTOP) right after a 60 s frame and key.

Every one ends what it started (``POST /stop`` at its end) and reports whether a vibration
stayed on that should not have (``stayed_on``).
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
from websockets.asyncio.client import connect

from phantomtouch.service.admission.policy import BHAPTICS_DEADLINE_S
from tests.bhaptics.player_client import PlayerClient, crowd_project, frame_submits
from tests.support.abuse_output import voices_on
from tests.support.owner_attacks import metric, stop_all

ROOT = Path(__file__).resolve().parents[2]


def huge_message(url: str, ws_url: str, bh_url: str) -> dict[str, Any]:
    """Two messages of 30,000 frame submits beside another client's moving contact.
    Returns the message's size, the statuses that answered, and whether the other
    client's contact was let go of (``released``)."""

    async def run() -> dict[str, Any]:
        heavy = frame_submits(30_000)
        released: list[Any] = []
        async with connect(ws_url) as ws:
            await ws.send(json.dumps({"type": "down", "contact": "hand", "x_cm": 1.9, "y_cm": 7.2}))

            async def mover() -> None:
                k = 0
                while True:
                    k += 1
                    y_cm = 7.0 + (k % 2) * 0.2
                    move = {"type": "move", "contact": "hand", "x_cm": 1.9, "y_cm": y_cm}
                    await ws.send(json.dumps(move))
                    await asyncio.sleep(1 / 30)

            async def reader() -> None:
                async for text in ws:
                    if json.loads(text).get("type") == "released":
                        released.append(text)

            tasks = [asyncio.create_task(mover()), asyncio.create_task(reader())]
            async with PlayerClient(bh_url) as game:
                for _ in range(2):
                    await game.send(heavy)
                answered = len(game.statuses) - 1
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        return {"bytes": len(heavy), "answered": answered, "released": bool(released)}

    seen = asyncio.run(run())
    stop_all(url)
    return seen


def idle_crowd(url: str, bh_url: str, crowd: int = 8) -> dict[str, Any]:
    """``crowd`` idle connections, then a game plays a 500 ms frame. Returns whether the
    game was served (its frame listed active) and how many idle ones yielded."""

    async def run() -> dict[str, Any]:
        idle = [await connect(bh_url, compression=None) for _ in range(crowd)]
        for ws in idle:
            await ws.recv()
        served = False
        try:
            async with PlayerClient(bh_url) as game:
                _, status = await game.send(
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
                served = "hello" in status["ActiveKeys"]
        except Exception:  # closed 1013 on connecting: not served
            served = False
        yielded = sum(ws.close_code is not None for ws in idle)
        for ws in idle:
            await ws.close()
        return {"served": served, "yielded": yielded}

    seen = asyncio.run(run())
    stop_all(url)
    return seen


def stop_while_planning(url: str, bh_url: str) -> dict[str, Any]:
    """A 200-voice, 8 s key; the stop 0.1 s after its submit. Returns whether the stop came
    while it was planned (``raced``) and the voices sounding 1 s after the stop
    (``stayed_on`` if any)."""

    async def run() -> dict[str, Any]:
        async with PlayerClient(bh_url) as game, httpx.AsyncClient(timeout=30.0) as http:
            crowd = crowd_project(200, 8000, 40)
            await game.send({"Register": [{"Key": "crowd", "Project": crowd}]})
            before = len(game.statuses)
            await game.ws.send(json.dumps({"Submit": [{"Type": "key", "Key": "crowd"}]}))
            await asyncio.sleep(0.1)
            await http.post(f"{url}/stop")
            stopped = time.monotonic()
            await game.wait_statuses(before + 1, timeout_s=120.0)
            raced = game.statuses[before][0] > stopped
            await asyncio.sleep(1.0)
            voices = voices_on(url)
        return {"raced": raced, "voices_after": voices, "stayed_on": voices > 0}

    seen = asyncio.run(run())
    stop_all(url)
    return seen


def hung_game(url: str, bh_url: str) -> dict[str, Any]:
    """A game plays a 60 s frame and key, then is frozen (SIGSTOP). Returns the contacts
    and voices on one deadline and a second later (``stayed_on`` if any)."""
    game = subprocess.Popen(
        [sys.executable, "-m", "tests.bhaptics.hung_game", bh_url, "60000"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert game.stdout is not None
        game.stdout.readline()
        game.send_signal(signal.SIGSTOP)
        time.sleep(BHAPTICS_DEADLINE_S + 1.0)
        contacts = metric(url, "phantomtouch_active_contacts")
        voices = voices_on(url)
    finally:
        game.kill()
        game.wait()
    stop_all(url)
    return {"contacts": contacts, "voices": voices, "stayed_on": contacts + voices > 0}
