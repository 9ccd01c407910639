"""The view's clock counts only time in which the registry answered.

While the registry stream elects a new leader (its server died) no node's heartbeat
lands. When writes resume, the first nodes through moved the view's clock past the TTL of
those whose heartbeat came a moment later, and a listing missed a live armband
(tests/fleet/test_server_loss.py under two CPU hogs: ``['l1', 'l3']`` once in 50). And a
failover longer than a fixed 10 s let every record expire at once (the same test, in a
whole-suite run: 36 of 50 lookups answered 404). Here a real bucket on a one-server
cluster is written by three "nodes" at the tests' heartbeat, then its server is killed
for eight TTLs (12 s) and started again, then two of the nodes write: the third stays listed
until the two have written for its TTL, then drops out. And nodes that all stop while the
registry answers drop out a TTL and a few heartbeats after their last write. And a watch
that delivers nothing while the nodes' writes land (a consumer reached through a server that
has only just come back: the same lookups in a later whole-suite run) expires nobody.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from phantomtouch.fleet.registry_view import SILENT_HEARTBEATS, RegistryView
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, open_registry
from tests.support.fleet_startup import HEARTBEAT_S, TTL_S, record
from tests.support.nats_cluster import NatsCluster

NODES = ["l1", "l2", "l3"]
OUTAGE_S = 8 * TTL_S
"""Longer than the 10 s for which the view's clock once stood still, s."""
LANDED_S = 20.0
"""How long a heartbeat may take to land once the server is back, s."""


async def _put(kv: Any, name: str) -> None:
    """Write ``name``'s record, again until it lands (the connection may be reconnecting)."""
    deadline_s = time.monotonic() + LANDED_S
    while True:
        try:
            await kv.put(name, record(name))
            return
        except Exception:
            if time.monotonic() > deadline_s:
                raise
            await asyncio.sleep(0.02)


async def _beat(kv: Any, names: list[str], beats: int) -> None:
    for _ in range(beats):
        for name in names:
            await _put(kv, name)
        await asyncio.sleep(HEARTBEAT_S)


class _Deafened:
    """The real registry bucket, except that once :attr:`deaf` is set its watches deliver
    nothing (their updates time out) while the bucket goes on taking writes."""

    def __init__(self, kv: Any) -> None:
        self.kv = kv
        self.deaf = False
        self.watches = 0

    async def status(self) -> Any:
        return await self.kv.status()

    async def watchall(self) -> Any:
        self.watches += 1
        return _Watch(await self.kv.watchall(), self)


class _Watch:
    def __init__(self, watcher: Any, bucket: _Deafened) -> None:
        self.watcher = watcher
        self.bucket = bucket

    async def updates(self, timeout: float) -> Any:
        if self.bucket.deaf:
            await asyncio.sleep(timeout)
            raise TimeoutError
        return await self.watcher.updates(timeout=timeout)

    async def stop(self) -> None:
        await self.watcher.stop()


def _listed(view: RegistryView) -> list[str]:
    return [r.armband for r in view.online()]


@contextlib.asynccontextmanager
async def _watched(
    cluster: NatsCluster, bucket: Callable[[Any], Any] = lambda kv: kv
) -> AsyncIterator[tuple[Any, RegistryView]]:
    """The registry bucket, after one heartbeat of every node, and a view of
    ``bucket(kv)`` started on it; both closed on leaving."""
    settings = FleetSettings(servers=cluster.urls, heartbeat_s=HEARTBEAT_S, ttl_s=TTL_S)
    nc, kv = await open_registry(settings, "gateway-test", Deadline(settings.start_deadline_s))
    view = RegistryView(bucket(kv))
    try:
        await _beat(kv, NODES, 1)
        await view.start("gateway test", Deadline(settings.start_deadline_s))
        yield kv, view
    finally:
        await view.close()
        await nc.close()


async def _outage(cluster: NatsCluster) -> dict[str, list[str]]:
    """What the view lists: before the outage, at its end, after the first writes that
    follow it, and once two nodes have written for a TTL and two heartbeats more."""
    async with _watched(cluster) as (kv, view):
        await _beat(kv, NODES, 4)
        seen = {"before": _listed(view)}
        await asyncio.to_thread(cluster.kill, 0)
        await asyncio.sleep(OUTAGE_S)
        await asyncio.to_thread(cluster.restart, 0)
        seen["outage"] = _listed(view)
        await _beat(kv, ["l1", "l3"], 1)
        seen["after"] = _listed(view)
        await _beat(kv, ["l1", "l3"], round(TTL_S / HEARTBEAT_S) + 2)
        seen["later"] = _listed(view)
    return seen


def test_an_outage_of_the_registry_counts_against_no_ttl(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        seen = asyncio.run(_outage(cluster))
    assert seen["before"] == NODES
    assert seen["outage"] == NODES, "a record expired while the registry did not answer"
    assert seen["after"] == NODES, "a live node dropped for the registry's outage"
    assert seen["later"] == ["l1", "l3"], "a node that stopped beating is still listed"


async def _gone_after_s(cluster: NatsCluster) -> float:
    """Seconds from the nodes' last heartbeat until the view lists none of them."""
    async with _watched(cluster) as (kv, view):
        await _beat(kv, NODES, 3)
        for name in NODES:
            await _put(kv, name)
        last_s = time.monotonic()
        assert _listed(view) == NODES
        while _listed(view) and time.monotonic() - last_s < OUTAGE_S:
            await asyncio.sleep(0.02)
        return time.monotonic() - last_s


def test_nodes_that_all_stop_drop_out_while_the_registry_answers(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        gone_s = asyncio.run(_gone_after_s(cluster))
    noticed_s = (SILENT_HEARTBEATS + 2) * HEARTBEAT_S  # the watch's silence, a pause, a watch
    print(f"every node gone {gone_s:.2f} s after its last heartbeat (TTL {TTL_S:g} s)")
    assert gone_s >= TTL_S, "a record expired before its TTL"
    assert gone_s < TTL_S + noticed_s + 2.0, "dead nodes listed long after their TTL"


async def _listed_through_a_deaf_watch(cluster: NatsCluster) -> tuple[list[str], int]:
    """What the view lists when its watches deliver nothing while every node goes on
    beating for four TTLs; how many watches it started."""
    buckets: list[_Deafened] = []

    def deafened(kv: Any) -> _Deafened:
        buckets.append(_Deafened(kv))
        return buckets[0]

    async with _watched(cluster, deafened) as (kv, view):
        await _beat(kv, NODES, 2)
        buckets[0].deaf = True
        await _beat(kv, NODES, round(4 * TTL_S / HEARTBEAT_S))
        return _listed(view), buckets[0].watches


def test_a_watch_that_delivers_nothing_while_nodes_beat_expires_nobody(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        listed, watches = asyncio.run(_listed_through_a_deaf_watch(cluster))
    assert watches >= 3, "the view did not start its watch again"
    assert listed == NODES, "a live node dropped while the view could not read the registry"
