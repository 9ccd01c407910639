"""The fleet's start-up path, run in several processes at the same instant, many rounds.

Each worker process plays one node or one gateway: at every round all workers and the
coordinator meet at a barrier, then each runs what a ``serve --fleet`` node or a
``gateway`` runs at start (:func:`phantomtouch.fleet.startup.open_registry`, then
:func:`~phantomtouch.fleet.startup.announce` for a node, a
:class:`~phantomtouch.fleet.registry_view.RegistryView` for a gateway) against the real
NATS cluster, reports, and meets the others again; between rounds the coordinator deletes
the registry bucket, so every round races to create it afresh. What is left out of a full
process start is only the web server and the engine, which come before the fleet's part
and cost seconds of CPU each on a small machine.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import time
from dataclasses import dataclass
from typing import Any

from phantomtouch.fleet.records import ArmbandRecord, Load

HEARTBEAT_S = 0.25
TTL_S = 1.5
LISTED_WITHIN_S = 10.0
BARRIER_TIMEOUT_S = 120.0


@dataclass(frozen=True)
class Outcome:
    """One worker's start in one round: ``ok`` or the one-line reason it failed."""

    round: int
    name: str
    outcome: str
    elapsed_s: float


def record(armband: str) -> bytes:
    """A registry record as a node on the null output writes it."""
    return (
        ArmbandRecord(
            armband=armband,
            site="lab",
            device={"channels": 8, "sample_rate_hz": 48000, "block_frames": 256, "actuators": []},
            output="null",
            status="ok",
            load=Load(active_voices=0, voice_capacity=64, active_contacts=0, underruns=0),
            server_time_s=time.monotonic(),
            unix_time_s=time.time(),
            clock_offset_s=None,
            heartbeat_s=HEARTBEAT_S,
            ttl_s=TTL_S,
            version="test",
        )
        .model_dump_json()
        .encode()
    )


class _Node:
    """A joined node: its connection, its watch and its heartbeats."""

    def __init__(self, nc: Any, watcher: Any, beats: asyncio.Task[None]) -> None:
        self.nc = nc
        self.watcher = watcher
        self.beats = beats

    async def close(self) -> None:
        self.beats.cancel()
        with contextlib.suppress(Exception):
            await self.watcher.stop()
        await self.nc.close()


async def _join_node(settings: Any, name: str) -> _Node:
    from phantomtouch.fleet.startup import Deadline, announce, open_registry

    deadline = Deadline(settings.start_deadline_s)
    nc, kv = await open_registry(settings, f"armband-{name}", deadline)

    async def beat() -> None:
        await kv.put(name, record(name))

    async def beats() -> None:
        while True:
            await asyncio.sleep(HEARTBEAT_S)
            with contextlib.suppress(Exception):
                await beat()

    try:
        watcher = await announce(kv, name, beat, deadline)
    except BaseException:
        await nc.close()
        raise
    return _Node(nc, watcher, asyncio.create_task(beats()))


async def _gateway_round(settings: Any, nodes: list[str]) -> str:
    from phantomtouch.fleet.registry_view import RegistryView
    from phantomtouch.fleet.startup import Deadline, open_registry

    deadline = Deadline(settings.start_deadline_s)
    nc, kv = await open_registry(settings, "gateway-test", deadline)
    view = RegistryView(kv)
    try:
        await view.start("gateway test", deadline)
        end_s = time.monotonic() + LISTED_WITHIN_S
        listed: set[str] = set()
        while time.monotonic() < end_s:
            listed = {r.armband for r in view.online()}
            if listed == set(nodes):
                return "ok"
            await asyncio.sleep(0.02)
        return f"listed {sorted(listed)} of {nodes} after {LISTED_WITHIN_S} s"
    finally:
        await view.close()
        await nc.close()


def worker(
    role: str,
    name: str,
    servers: str,
    nodes: list[str],
    rounds: int,
    deadline_s: float,
    barrier: Any,
    results: Any,
) -> None:
    """Run ``rounds`` starts as ``role`` (``node`` or ``gateway``), each at the barrier.

    Per round the barrier is met three times: to start together, once every worker has
    reported (nodes keep beating until then, so the gateway can list them), and once
    every connection is closed (then the coordinator deletes the bucket).
    """
    from phantomtouch.fleet.errors import FleetJoinError
    from phantomtouch.fleet.settings import FleetSettings

    settings = FleetSettings(
        servers=servers, heartbeat_s=HEARTBEAT_S, ttl_s=TTL_S, start_deadline_s=deadline_s
    )

    async def meet() -> None:
        await asyncio.to_thread(barrier.wait, BARRIER_TIMEOUT_S)

    async def one_round(index: int) -> None:
        await meet()
        started_s = time.monotonic()
        node: _Node | None = None
        try:
            if role == "node":
                node = await _join_node(settings, name)
                outcome = "ok"
            else:
                outcome = await _gateway_round(settings, nodes)
        except FleetJoinError as exc:
            outcome = str(exc)
        results.put(Outcome(index, name, outcome, time.monotonic() - started_s))
        await meet()
        if node is not None:
            await node.close()
        await meet()

    async def all_rounds() -> None:
        for index in range(rounds):
            await one_round(index)

    asyncio.run(all_rounds())


def run_rounds(servers: str, rounds: int, deadline_s: float) -> list[Outcome]:
    """Three nodes and a gateway started together ``rounds`` times against ``servers``,
    the registry bucket deleted before each round; every worker's outcome of every round."""
    nodes = ["s1", "s2", "s3"]
    context = multiprocessing.get_context("spawn")
    barrier = context.Barrier(len(nodes) + 2)
    results = context.Queue()
    roles = [("node", name) for name in nodes] + [("gateway", "gateway")]
    processes = [
        context.Process(
            target=worker,
            args=(role, name, servers, nodes, rounds, deadline_s, barrier, results),
            daemon=True,
        )
        for role, name in roles
    ]
    for process in processes:
        process.start()
    outcomes: list[Outcome] = []
    try:
        for _ in range(rounds):
            asyncio.run(delete_bucket(servers))
            barrier.wait(BARRIER_TIMEOUT_S)  # start
            barrier.wait(BARRIER_TIMEOUT_S)  # reported
            outcomes += [results.get(timeout=5.0) for _ in roles]
            barrier.wait(BARRIER_TIMEOUT_S)  # closed
    except BaseException:
        barrier.abort()
        raise
    finally:
        for process in processes:
            process.join(10.0)
            if process.is_alive():
                process.kill()
    return outcomes


async def delete_bucket(servers: str) -> None:
    """Delete the registry bucket if it exists (each round then creates it afresh)."""
    import nats
    import nats.js.errors

    from phantomtouch.fleet.subjects import REGISTRY_BUCKET

    nc = await nats.connect(servers.split(","))
    try:
        for _ in range(50):
            try:
                await nc.jetstream(timeout=5.0).delete_key_value(REGISTRY_BUCKET)
                return
            except nats.js.errors.NotFoundError:
                return
            except (nats.errors.Error, TimeoutError):
                await asyncio.sleep(0.2)
    finally:
        await nc.close()
