"""Reads through a server loss: the gateway answers listings from its view of the registry.

A fleet of its own (the module's fleet of tests/fleet/conftest.py is shared with tests
that need every server up): a 3-server cluster, three nodes, one gateway. The server
the gateway is connected to is killed, and the armbands are listed 50 times while the
cluster fails over: none of the listings may fail or miss an armband.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import httpx
import pytest

from tests.support.fleet import ArmbandNode, Gateway
from tests.support.live_server import HOST
from tests.support.nats_cluster import NatsCluster
from tests.support.waiting import wait_until

LISTINGS = 50
PAUSE_S = 0.1
ARMBANDS = {"l1", "l2", "l3"}


@pytest.fixture(scope="module")
def small_fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[NatsCluster, Gateway]]:
    folder = tmp_path_factory.mktemp("loss")
    cluster = NatsCluster(folder / "nats").start()
    nodes = [ArmbandNode(folder, cluster, armband, "lab") for armband in sorted(ARMBANDS)]
    gateway = Gateway(folder, cluster)
    try:
        for node in nodes:
            node.start()
        gateway.start()
        yield cluster, gateway
    finally:
        gateway.stop()
        for node in nodes:
            node.stop()
        cluster.stop()


def server_of(cluster: NatsCluster, prefix: str) -> int:
    """The index of the server a client named ``prefix…`` is connected to."""
    for index, port in enumerate(cluster.monitor_ports):
        if cluster.processes[index] is None:
            continue
        connz = httpx.get(f"http://{HOST}:{port}/connz", timeout=2.0).json()
        if any(c.get("name", "").startswith(prefix) for c in connz.get("connections") or []):
            return index
    raise AssertionError(f"no server has a client named {prefix}…")


def listed(gateway: Gateway) -> tuple[int, set[str]]:
    answer = httpx.get(f"{gateway.url}/armbands", timeout=10.0)
    armbands = {r["armband"] for r in answer.json()} if answer.status_code == 200 else set()
    return answer.status_code, armbands


def test_listings_go_on_while_the_gateways_server_dies(
    small_fleet: tuple[NatsCluster, Gateway],
) -> None:
    cluster, gateway = small_fleet
    wait_until(lambda: listed(gateway) == (200, ARMBANDS), 10.0, "every armband listed")
    index = server_of(cluster, "gateway-")
    cluster.kill(index)
    try:
        killed_s = time.monotonic()
        failures = []
        for attempt in range(LISTINGS):
            status, armbands = listed(gateway)
            if (status, armbands) != (200, ARMBANDS):
                failures.append((attempt, status, sorted(armbands)))
            time.sleep(PAUSE_S)
        spent_s = time.monotonic() - killed_s
        print(f"{LISTINGS} listings over {spent_s:.1f} s after the server died: {failures}")
        assert failures == []
        assert server_of(cluster, "gateway-") != index
    finally:
        cluster.restart(index)


def test_lookups_go_on_while_the_gateways_server_dies(
    small_fleet: tuple[NatsCluster, Gateway],
) -> None:
    cluster, gateway = small_fleet
    wait_until(lambda: listed(gateway) == (200, ARMBANDS), 20.0, "every armband listed")
    index = server_of(cluster, "gateway-")
    cluster.kill(index)
    try:
        statuses = []
        for attempt in range(LISTINGS):
            armband = sorted(ARMBANDS)[attempt % len(ARMBANDS)]
            statuses.append(httpx.get(f"{gateway.url}/armbands/{armband}", timeout=10.0))
            time.sleep(PAUSE_S)
        failed = [(a.status_code, a.text[:120]) for a in statuses if a.status_code != 200]
        assert failed == []
    finally:
        cluster.restart(index)
