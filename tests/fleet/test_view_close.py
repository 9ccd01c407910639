"""A gateway's registry view closes while the nodes' records stream in, every time.

A single cancel of the view's follower was now and then swallowed (on Python 3.11
``asyncio.wait_for``, inside the watch's ``updates``, returns an update that arrives with
the cancel instead of raising it), and :meth:`RegistryView.close` then waited for ever on
a follower that went on reading: the gateway of tests/fleet/test_startup.py never
reported its round. Here the real bucket of a real NATS server is written as fast as it
takes the puts, and a view is started and closed again and again; a close that is still
waiting while the writers have made :data:`PUTS_WHILE_CLOSING` more puts counts as stuck.
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

from phantomtouch.fleet.registry_view import RegistryView
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, open_registry
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
