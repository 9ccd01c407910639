"""A heartbeat lost with its server does not let the armband's record expire.

A 3-server cluster, two nodes and a gateway. Node ``h1`` is connected to a server that
does not lead the registry's stream; that server is paused (SIGSTOP) so that a heartbeat
of ``h1`` waits on it, then killed. ``h1`` reconnects to another server at once, but the
lost heartbeat's request is still waiting for its reply; while it waits, no heartbeat
of ``h1`` is written. Node ``h2`` keeps beating meanwhile, so the gateway's view of the
registry moves on, and ``h1``'s record must not grow older than its TTL: every lookup
of ``h1`` at the gateway answers 200. Each heartbeat waits at most the bound of
``FleetSettings.beat_timeout_s`` (0.625 s with the tests' 0.25 s heartbeat and 1.5 s TTL,
where the request's own timeout is 2 s).
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import httpx
import pytest

from phantomtouch.fleet.subjects import REGISTRY_BUCKET
from tests.support.fleet import HEARTBEAT_S, TTL_S, ArmbandNode, Gateway
from tests.support.live_server import HOST
from tests.support.nats_cluster import NatsCluster
from tests.support.waiting import wait_until

PAUSED_S = 2 * HEARTBEAT_S
"""How long the server stays paused before it is killed: a heartbeat is sent into it."""
WATCHED_S = 3 * TTL_S
"""How long the lookups go on after the kill, s."""


def stream_leader(cluster: NatsCluster) -> str:
    """The name (``n<index>``) of the server that leads the registry's stream ("" when
    none does yet)."""
    port = cluster.monitor_ports[0]
    jsz = httpx.get(f"http://{HOST}:{port}/jsz?accounts=true&streams=true", timeout=5.0).json()
    for account in jsz.get("account_details") or []:
        for stream in account.get("stream_detail") or []:
            if stream["name"] == f"KV_{REGISTRY_BUCKET}" and stream.get("cluster"):
                return str(stream["cluster"].get("leader") or "")
    return ""


def test_a_heartbeat_lost_with_its_server_does_not_expire_the_record(tmp_path: Path) -> None:
    if sys.platform == "win32":
        pytest.skip("SIGSTOP is POSIX")
    cluster = NatsCluster(tmp_path / "nats").start()
    nodes: list[ArmbandNode] = []
    gateway = Gateway(tmp_path, cluster, servers=cluster.urls[0])
    try:
        nodes.append(ArmbandNode(tmp_path, cluster, "h2", "lab", servers=cluster.urls[0]).start())
        gateway.start()
        wait_until(lambda: stream_leader(cluster) != "", 20.0, "a leader of the registry")
        leader = stream_leader(cluster)
        victim = next(index for index in (1, 2) if f"n{index}" != leader)
        nodes.append(
            ArmbandNode(tmp_path, cluster, "h1", "lab", servers=cluster.urls[victim]).start()
        )
        lookup = f"{gateway.url}/armbands/h1"
        wait_until(lambda: httpx.get(lookup, timeout=5.0).status_code == 200, 20.0, "h1 listed")
        process = cluster.processes[victim]
        assert process is not None
        os.kill(process.pid, signal.SIGSTOP)
        time.sleep(PAUSED_S)
        cluster.kill(victim)
        killed_s = time.monotonic()
        statuses = []
        while time.monotonic() - killed_s < WATCHED_S:
            statuses.append(httpx.get(lookup, timeout=10.0).status_code)
            time.sleep(0.05)
        h2 = httpx.get(f"{gateway.url}/armbands/h2", timeout=10.0).status_code
        print(f"lookups of h1 after the kill: {statuses}")
        assert h2 == 200, "the other node's heartbeats must go on for the test to mean anything"
        assert [status for status in statuses if status != 200] == []
    finally:
        gateway.stop()
        for node in nodes:
            node.stop()
        cluster.stop()
