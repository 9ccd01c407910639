"""Programs that try to take the armband from other clients, bounded in time, loopback only.

Each is meant to run in a process of its own (:func:`tests.support.abuse.in_process`):
flooding ``play`` from several WebSocket connections or several loopback addresses, and
holding every contact slot through many connections. :func:`victim_touch` is the other
client: one touch, and the state it ends in.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from typing import Any

import httpx
from websockets.asyncio.client import connect

FLOOD: dict[str, Any] = {"preset": "exp2/curved"}
VICTIM: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
    "duration_s": 3.0,
}
"""The other client's touch: 3 s along the arm."""


def ws_play_flood(ws_url: str, seconds: float, connections: int = 2) -> dict[str, int]:
    """``play`` back to back on ``connections`` connections for ``seconds``; answers by kind."""

    async def one(counts: dict[str, int]) -> None:
        async with connect(ws_url) as ws:
            k = 0
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                k += 1
                await ws.send(json.dumps({"type": "play", "id": k, **FLOOD}))
                while True:
                    answer = json.loads(await ws.recv())
                    if answer.get("id") == k:
                        kind = answer["type"] if answer["type"] == "ok" else answer["code"]
                        counts[kind] = counts.get(kind, 0) + 1
                        break

    async def flood() -> dict[str, int]:
        counts: dict[str, int] = {}
        await asyncio.gather(*(one(counts) for _ in range(connections)))
        return counts

    return asyncio.run(flood())


def http_play_flood(url: str, seconds: float, addresses: tuple[str, ...]) -> dict[str, int]:
    """``POST /touch`` back to back from each of ``addresses`` (two at a time each)."""

    async def one(address: str, counts: dict[str, int]) -> None:
        transport = httpx.AsyncHTTPTransport(local_address=address)
        async with httpx.AsyncClient(base_url=url, timeout=10, transport=transport) as client:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                status = str((await client.post("/touch", json=FLOOD)).status_code)
                counts[status] = counts.get(status, 0) + 1

    async def flood() -> dict[str, int]:
        counts: dict[str, int] = {}
        await asyncio.gather(*(one(a, counts) for a in addresses for _ in range(2)))
        return counts

    return asyncio.run(flood())


def contact_hoard(ws_url: str, seconds: float, connections: int = 13) -> dict[str, int]:
    """Hold 10 contacts on each of ``connections`` connections for ``seconds`` (pinging);
    the answers to the downs by kind, and the contacts released by ``quota``."""

    async def hoard() -> dict[str, int]:
        counts: dict[str, int] = {}
        async with contextlib.AsyncExitStack() as stack:
            held = [await stack.enter_async_context(connect(ws_url)) for _ in range(connections)]
            for k, ws in enumerate(held):
                for finger in range(10):
                    down = {"type": "down", "contact": f"c{k}-{finger}", "x_cm": 1.9}
                    await ws.send(json.dumps({**down, "y_cm": 7.2, "id": finger}))
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                for ws in held:
                    await ws.send(json.dumps({"type": "ping"}))
                    with contextlib.suppress(TimeoutError):
                        while True:
                            answer = json.loads(await asyncio.wait_for(ws.recv(), 0.01))
                            kind = answer.get("reason") or answer.get("code") or answer["type"]
                            counts[kind] = counts.get(kind, 0) + 1
                await asyncio.sleep(0.2)
        return counts

    return asyncio.run(hoard())


def victim_touch(url: str) -> str:
    """One client's touch (:data:`VICTIM`): the state it ends in (``finished`` when it
    played to its end, ``stopped`` when it was stolen)."""
    with httpx.Client(base_url=url, timeout=10) as client:
        for _ in range(100):  # a voice beginning may be refused busy under a flood
            answer = client.post("/touch", json=VICTIM)
            if answer.status_code != 503:
                break
            time.sleep(0.02)
        if answer.status_code != 202:
            return f"refused {answer.status_code}"
        job_id = answer.json()["job_id"]
        deadline = time.monotonic() + VICTIM["duration_s"] + 10.0
        while time.monotonic() < deadline:
            state = str(client.get(f"/jobs/{job_id}").json()["state"])
            if state in ("finished", "stopped"):
                return state
            time.sleep(0.1)
    return "still playing"


def victim_contact(ws_url: str) -> str:
    """One client's ``down``: the answer's type (``ok``) or error code (``busy``)."""

    async def down() -> str:
        async with connect(ws_url) as ws:
            message = {"type": "down", "contact": "mine", "x_cm": 1.9, "y_cm": 7.2, "id": 1}
            await ws.send(json.dumps(message))
            while True:
                answer = json.loads(await asyncio.wait_for(ws.recv(), 5))
                if answer.get("id") == 1:
                    return str(answer["type"] if answer["type"] == "ok" else answer["code"])

    return asyncio.run(down())
