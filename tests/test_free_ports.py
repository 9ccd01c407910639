"""The test servers' ports are distinct. Chosen one at a time by binding port 0, a port
could come back from the next choice (9 ports repeated one in 5 of 2,000 draws; 2,000
ports drawn one at a time repeated 136 to 152 times), and a NATS server given the same
port for two listeners exited at start."""

from __future__ import annotations

from pathlib import Path

from tests.support.live_server import free_port, free_ports
from tests.support.nats_cluster import NatsCluster


def test_ports_chosen_together_are_distinct() -> None:
    ports = free_ports(200)
    assert len(set(ports)) == 200
    assert all(1024 <= port <= 65535 for port in ports)


def test_ports_chosen_one_at_a_time_are_distinct() -> None:
    """Servers built one after another (each with its own port) before any listens."""
    ports = [free_port() for _ in range(2000)]
    assert len(set(ports)) == 2000


def test_a_clusters_ports_are_distinct(tmp_path: Path) -> None:
    for _ in range(50):
        cluster = NatsCluster(tmp_path / "nats")
        ports = cluster.client_ports + cluster.cluster_ports + cluster.monitor_ports
        assert len(set(ports)) == len(ports) == 9, ports
