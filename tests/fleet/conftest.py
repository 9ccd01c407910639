"""One fleet per test module: a 3-server NATS cluster closed by the configuration of
``phantomtouch fleet-config``, 3 armband nodes, 2 gateways."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from phantomtouch.fleet.nats_config import plan
from tests.support.fleet import ArmbandNode, Gateway
from tests.support.nats_cluster import NatsCluster

SITES = {"a1": "lab-a", "a2": "lab-a", "a3": "lab-b"}
SPARE = {"a4": "lab-c"}
"""An armband with a user of its own, which tests start and kill."""
GATEWAYS = ["gw0", "gw1"]
CLIENT = "game-server"
"""A user with a gateway's permissions, for tests that speak NATS directly."""
MORE_GATEWAYS = "gateway"
"""The user of gateways that tests start on the fleet beside its two."""


@dataclass
class Fleet:
    cluster: NatsCluster
    nodes: dict[str, ArmbandNode]
    gateways: list[Gateway]
    folder: Path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    folder = tmp_path_factory.mktemp("fleet")
    users = plan([*SITES.items(), *SPARE.items()], [*GATEWAYS, MORE_GATEWAYS, CLIENT])
    cluster = NatsCluster(folder / "nats", users=users).start()
    nodes: dict[str, ArmbandNode] = {}
    gateways: list[Gateway] = []
    try:
        for armband, site in SITES.items():
            nodes[armband] = ArmbandNode(folder, cluster, armband, site)
            nodes[armband].start()
        gateways = [Gateway(folder, cluster, name=name).start() for name in GATEWAYS]
        yield Fleet(cluster, nodes, gateways, folder)
    finally:
        for gateway in gateways:
            gateway.stop()
        for node in nodes.values():
            node.stop()
        cluster.stop()
