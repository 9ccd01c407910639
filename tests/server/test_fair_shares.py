"""Fair shares against many connections, on a live server (the null output, loopback).

Voices are stolen from whoever holds the most, contacts taken from the largest holder:
a program that opens more connections, or speaks from more loopback addresses, cannot
take another client's touch or contact (max-min fairness, :mod:`phantomtouch.engine.owners`
and :meth:`phantomtouch.engine.jobs.JobTable.admit`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Awaitable, Callable, Iterator
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import ClientConnection, connect

from tests.support.live_server import LiveServer

FLOOD = {"preset": "exp2/curved"}
VICTIM = {"path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]}, "duration_s": 3.0}
TRIALS = 5
FLOOD_ADDRESSES = ("127.0.0.4", "127.0.0.5", "127.0.0.6", "127.0.0.7")


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("fair")
    # contacts held while a test fills every slot stay down without pings
    with LiveServer(folder / "patterns.db", env={"PHANTOMTOUCH_WATCHDOG_S": "30"}) as server:
        yield server


async def ws_flood(ws: ClientConnection, stop: asyncio.Event, answers: list[str]) -> None:
    """``play`` back to back on one connection, each after the answer to the last."""
    k = 0
    while not stop.is_set():
        k += 1
        await ws.send(json.dumps({"type": "play", "id": k, **FLOOD}))
        while True:
            answer = json.loads(await ws.recv())
            if answer.get("id") == k:
                if answer["type"] == "ok":
                    answers.append(answer["result"]["job_id"])
                break
        await asyncio.sleep(0)


async def http_flood(client: httpx.AsyncClient, stop: asyncio.Event, answers: list[str]) -> None:
    while not stop.is_set():
        answer = await client.post("/touch", json=FLOOD)
        if answer.status_code == 202:
            answers.append(answer.json()["job_id"])


async def victim_touch(live: LiveServer) -> str:
    """One client's touch of 3 s while the flood goes on: the state it ends in."""
    async with httpx.AsyncClient(base_url=live.url, timeout=10) as client:
        for _ in range(100):  # a voice beginning may be refused busy under the flood
            answer = await client.post("/touch", json=VICTIM)
            if answer.status_code != 503:
                break
            await asyncio.sleep(0.02)
        assert answer.status_code == 202, answer.text
        job_id = answer.json()["job_id"]
        deadline = time.monotonic() + VICTIM["duration_s"] + 10.0
        while time.monotonic() < deadline:
            state = (await client.get(f"/jobs/{job_id}")).json()["state"]
            if state in ("finished", "stopped"):
                return str(state)
            await asyncio.sleep(0.1)
    return "still playing"


async def stolen(live: LiveServer, job_ids: list[str]) -> int:
    """How many of the jobs were stopped (none of them was asked to stop: stolen)."""
    async with httpx.AsyncClient(base_url=live.url, timeout=10) as client:
        states = [(await client.get(f"/jobs/{job_id}")).json()["state"] for job_id in job_ids]
    return states.count("stopped")


async def trials_under(
    live: LiveServer, flood: Callable[[asyncio.Event, list[str]], list[Awaitable[None]]]
) -> tuple[list[str], int]:
    """The victim's trials while ``flood`` runs; how many flood jobs were stolen meanwhile."""
    stop = asyncio.Event()
    answers: list[str] = []
    tasks = [asyncio.ensure_future(f) for f in flood(stop, answers)]
    try:
        await asyncio.sleep(1.0)  # the flood fills the voices
        ends = [await victim_touch(live) for _ in range(TRIALS)]
    finally:
        stop.set()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    async with httpx.AsyncClient(base_url=live.url) as client:
        await client.post("/stop")
    return ends, await stolen(live, answers[-900:])


def test_two_flooding_connections_cannot_steal_another_clients_touch(live: LiveServer) -> None:
    async def scenario() -> tuple[list[str], int]:
        async with connect(live.ws_url) as first, connect(live.ws_url) as second:
            return await trials_under(
                live,
                lambda stop, answers: [
                    ws_flood(first, stop, answers),
                    ws_flood(second, stop, answers),
                ],
            )

    ends, flood_stolen = asyncio.run(scenario())
    assert flood_stolen > 0, "the flood filled the voices: voices were stolen meanwhile"
    assert ends == ["finished"] * TRIALS


def test_four_flooding_addresses_cannot_steal_another_clients_touch(live: LiveServer) -> None:
    async def scenario() -> tuple[list[str], int]:
        async with contextlib.AsyncExitStack() as stack:
            clients = [
                await stack.enter_async_context(
                    httpx.AsyncClient(
                        base_url=live.url,
                        timeout=10,
                        transport=httpx.AsyncHTTPTransport(local_address=address),
                    )
                )
                for address in FLOOD_ADDRESSES
            ]
            return await trials_under(
                live,
                lambda stop, answers: [
                    http_flood(client, stop, answers) for client in clients for _ in range(2)
                ],
            )

    ends, flood_stolen = asyncio.run(scenario())
    assert flood_stolen > 0, "the flood filled the voices: voices were stolen meanwhile"
    assert ends == ["finished"] * TRIALS


async def down(ws: ClientConnection, contact: str, message_id: int) -> dict[str, Any]:
    """Put a contact down; the answer to it (``released`` notices are skipped)."""
    await ws.send(
        json.dumps({"type": "down", "contact": contact, "x_cm": 1.9, "y_cm": 7.2, "id": message_id})
    )
    while True:
        answer: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), 5))
        if answer.get("id") == message_id:
            return answer


async def notices_of(ws: ClientConnection) -> list[dict[str, Any]]:
    """What the server sent ``ws`` unasked, within half a second."""
    notices = []
    with contextlib.suppress(TimeoutError):
        while True:
            notices.append(json.loads(await asyncio.wait_for(ws.recv(), 0.5)))
    return notices


async def active_contacts(live: LiveServer) -> float:
    async with httpx.AsyncClient(base_url=live.url) as client:
        metrics = (await client.get("/metrics")).text
    line = next(x for x in metrics.splitlines() if x.startswith("phantomtouch_active_contacts "))
    return float(line.split()[1])


def test_a_down_gets_a_slot_from_a_program_holding_every_contact(live: LiveServer) -> None:
    async def scenario() -> None:
        async with contextlib.AsyncExitStack() as stack:
            holders = [await stack.enter_async_context(connect(live.ws_url)) for _ in range(13)]
            for k, ws in enumerate(holders):
                for finger in range(10):
                    await down(ws, f"c{k}-{finger}", finger)
            for ws in holders:  # the program's own connections evened out its shares
                await notices_of(ws)
            assert await active_contacts(live) == 128, "the program holds every slot"
            other = await stack.enter_async_context(connect(live.ws_url))
            assert await down(other, "mine", 1) == {"type": "ok", "id": 1}
            notices = [notice for ws in holders for notice in await notices_of(ws)]
            assert len(notices) == 1, notices
            assert notices[0]["type"] == "released"
            assert notices[0]["reason"] == "quota"
            assert len(notices[0]["contacts"]) == 1
            assert await active_contacts(live) == 128
        async with httpx.AsyncClient(base_url=live.url) as client:
            await client.post("/stop")

    asyncio.run(scenario())
