"""A time in which the registry took no writes does not count against any record's TTL.

While the registry stream elects a new leader (its server died) no node's heartbeat
lands. When writes resume, the first nodes through moved the view's clock past the TTL of
those whose heartbeat came a moment later, and a listing missed a live armband
(tests/fleet/test_server_loss.py under two CPU hogs: ``['l1', 'l3']`` once in 50). Here a
real bucket is written by three "nodes" at the tests' heartbeat, then not at all for three
TTLs (the view's watch falls silent and is started again, replaying every key), then by
two of them: the third stays listed until the two have written for its TTL, then drops out.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

from phantomtouch.fleet.registry_view import RegistryView
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, open_registry
from tests.support.fleet_startup import HEARTBEAT_S, TTL_S, record
from tests.support.nats_cluster import NatsCluster

NODES = ["l1", "l2", "l3"]
SILENCE_S = 3 * TTL_S


async def _listings(cluster: NatsCluster) -> dict[str, list[str]]:
    """What the view lists: before the silence, during it, after the first writes that
    follow it, and once two nodes have written for a TTL and two heartbeats more."""
    settings = FleetSettings(servers=cluster.urls, heartbeat_s=HEARTBEAT_S, ttl_s=TTL_S)
    nc, kv = await open_registry(settings, "gateway-test", Deadline(settings.start_deadline_s))
    view = RegistryView(kv)

    async def beat(names: list[str], beats: int) -> None:
        for _ in range(beats):
            for name in names:
                await kv.put(name, record(name))
            await asyncio.sleep(HEARTBEAT_S)

    def listed() -> list[str]:
        return [r.armband for r in view.online()]

    try:
        await beat(NODES, 1)
        await view.start("gateway test", Deadline(settings.start_deadline_s))
        await beat(NODES, 4)
        seen = {"before": listed()}
        await asyncio.sleep(SILENCE_S)
        seen["silence"] = listed()
        await beat(["l1", "l3"], 1)
        seen["after"] = listed()
        await beat(["l1", "l3"], round(TTL_S / HEARTBEAT_S) + 2)
        seen["later"] = listed()
    finally:
        await view.close()
        await nc.close()
    return seen


def test_a_silence_of_the_registry_counts_against_no_ttl(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        seen = asyncio.run(_listings(cluster))
    assert seen["before"] == NODES
    assert seen["silence"] == NODES
    assert seen["after"] == NODES, "a live node dropped for the registry's silence"
    assert seen["later"] == ["l1", "l3"], "a node that stopped beating is still listed"
