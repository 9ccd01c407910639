"""One fleet per test module: a 3-server NATS cluster, 3 armband nodes, 2 gateways."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.support.fleet import ArmbandNode, Gateway
from tests.support.nats_cluster import NatsCluster

SITES = {"a1": "lab-a", "a2": "lab-a", "a3": "lab-b"}


@dataclass
class Fleet:
    cluster: NatsCluster
    nodes: dict[str, ArmbandNode]
    gateways: list[Gateway]
    folder: Path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    folder = tmp_path_factory.mktemp("fleet")
    cluster = NatsCluster(folder / "nats").start()
    nodes: dict[str, ArmbandNode] = {}
    gateways: list[Gateway] = []
    try:
        for armband, site in SITES.items():
            nodes[armband] = ArmbandNode(folder, cluster, armband, site)
            nodes[armband].start()
        gateways = [Gateway(folder, cluster).start() for _ in range(2)]
        yield Fleet(cluster, nodes, gateways, folder)
    finally:
        for gateway in gateways:
            gateway.stop()
        for node in nodes.values():
            node.stop()
        cluster.stop()
