"""A gateway's registry view closes while the nodes' records stream in, every time.

A single cancel of the view's follower was now and then swallowed (on Python 3.11
``asyncio.wait_for``, inside the watch's ``updates``, returns an update that arrives with
the cancel instead of raising it), and :meth:`RegistryView.close` then waited for ever on
a follower that went on reading: the gateway of tests/fleet/test_startup.py never
reported its round. Here the real bucket of a real NATS server is written as fast as it
takes the puts, and a view is started and closed again and again; a close that is still
waiting while the writers have made :data:`PUTS_WHILE_CLOSING` more puts counts as stuck.
A node's loops that read a watch (its heartbeats' time stamps) end the same way, through
:func:`~phantomtouch.fleet.tasks.cancel_until_done`, which the node's close awaits.
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

from phantomtouch.fleet.registry_view import RegistryView
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, open_registry
from phantomtouch.fleet.tasks import cancel_until_done
from tests.support.fleet_startup import HEARTBEAT_S, TTL_S, record
from tests.support.nats_cluster import NatsCluster

CYCLES = 100
PUTS_WHILE_CLOSING = 1000
"""Puts the writers make during a close that has not returned before it counts as stuck
(a close that ends takes a few of the event loop's turns, a handful of puts)."""
NODES = ["s1", "s2", "s3"]


async def _stuck_closes(cluster: NatsCluster) -> list[int]:
    """The cycles whose close was still waiting after :data:`PUTS_WHILE_CLOSING` puts."""
    settings = FleetSettings(servers=cluster.urls, heartbeat_s=HEARTBEAT_S, ttl_s=TTL_S)
    nc, kv = await open_registry(settings, "gateway-test", Deadline(settings.start_deadline_s))
    puts = 0
    writing = True

    async def write(name: str) -> None:
        nonlocal puts
        while writing:
            await kv.put(name, record(name))
            puts += 1

    writers = [asyncio.create_task(write(name)) for name in NODES]
    stuck: list[int] = []
    try:
        for cycle in range(CYCLES):
            view = RegistryView(kv)
            await view.start("gateway test", Deadline(settings.start_deadline_s))
            for _ in range(cycle % 7):
                await asyncio.sleep(0)
            closing = asyncio.create_task(view.close())
            puts_at_close = puts
            while not closing.done() and puts - puts_at_close < PUTS_WHILE_CLOSING:
                await asyncio.sleep(0.001)
            if not closing.done():
                stuck.append(cycle)
                await _end(view)
                break
    finally:
        writing = False
        for writer in writers:
            with contextlib.suppress(Exception):
                await writer
        await nc.close()
    return stuck


async def _end(view: RegistryView) -> None:
    """End a view whose close is stuck, so that the test can fail instead of waiting too."""
    follower = view._task
    while follower is not None and not follower.done():
        follower.cancel()
        await asyncio.wait({follower}, timeout=0.05)


def test_a_view_following_a_stream_of_records_closes_every_time(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        stuck = asyncio.run(_stuck_closes(cluster))
    assert stuck == []


async def _loops_left_running(cluster: NatsCluster) -> tuple[int, int]:
    """Of :data:`CYCLES` loops reading a watch under a stream of puts: how many a single
    cancel left running, and how many :func:`cancel_until_done` did."""
    settings = FleetSettings(servers=cluster.urls, heartbeat_s=HEARTBEAT_S, ttl_s=TTL_S)
    nc, kv = await open_registry(settings, "armband-s1", Deadline(settings.start_deadline_s))
    writing = True

    async def write() -> None:
        while writing:
            await kv.put("s1", record("s1"))

    async def read(watcher: object) -> None:  # the shape of the node's time stamp loop
        while True:
            with contextlib.suppress(Exception):
                await watcher.updates(timeout=TTL_S)  # type: ignore[attr-defined]

    writer = asyncio.create_task(write())
    left = [0, 0]
    try:
        for cycle in range(2 * CYCLES):
            watcher = await kv.watch("s1")
            loop = asyncio.create_task(read(watcher))
            for _ in range(cycle % 7 + 1):
                await asyncio.sleep(0)
            if cycle % 2 == 0:
                loop.cancel()
                await asyncio.wait({loop}, timeout=0.05)
                left[0] += not loop.done()
            await cancel_until_done(loop)
            left[1] += not loop.done()
            await watcher.stop()
    finally:
        writing = False
        with contextlib.suppress(Exception):
            await writer
        await nc.close()
    return left[0], left[1]


def test_loops_reading_a_watch_end_when_cancelled_until_done(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        single, until_done = asyncio.run(_loops_left_running(cluster))
    print(f"of {CYCLES} loops, a single cancel left {single} running")
    assert until_done == 0
