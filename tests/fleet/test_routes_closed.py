"""A fleet's NATS route ports are closed: a rogue server without credentials cannot join.

Real ``nats-server`` processes on loopback. The cluster runs the configuration
``phantomtouch fleet-config`` writes (client users and route authorization); a rogue
server, configured with a route to it and no credentials, tries to join, and its
anonymous client publishes on an armband's touch subject while the armband's node
listens on the cluster. With the routes closed nothing arrives; the same cluster with
its routes left open (as docs/fleet.md built it before) lets the rogue's touches through,
which shows the test can see them. The start-up probe refuses open route ports in one
line and says in one line when it cannot tell.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import nats
import pytest

from phantomtouch.errors import ParameterError
from phantomtouch.fleet import subjects
from phantomtouch.fleet.nats_config import plan
from phantomtouch.fleet.route_probe import check_routes
from tests.support.live_server import HOST, free_port, free_ports
from tests.support.nats_cluster import NatsCluster, require_nats_server

ROGUE_TRIES_S = 20.0
"""How long the rogue is given to join (it retries its route every second or so)."""


def _users() -> list:  # type: ignore[type-arg]
    return plan([("a1", "lab")], ["gw0"])


def _rogue(folder: Path, cluster: NatsCluster) -> tuple[subprocess.Popen[bytes], int, Path]:
    """A server of the cluster's name, routed to its first server, without credentials."""
    client_port, route_port, monitor_port = free_ports(3)
    config = folder / "rogue.conf"
    config.write_text(
        f"""
server_name: rogue
listen: {HOST}:{client_port}
http: {HOST}:{monitor_port}
cluster {{
  name: phantomtouch-test
  listen: {HOST}:{route_port}
  routes: [nats-route://{HOST}:{cluster.cluster_ports[0]}]
}}
"""
    )
    log = folder / "rogue.log"
    with log.open("ab") as out:
        process = subprocess.Popen(
            [require_nats_server(), "-c", str(config)], stdout=out, stderr=subprocess.STDOUT
        )
    deadline = time.monotonic() + ROGUE_TRIES_S
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://{HOST}:{monitor_port}/healthz", timeout=1).status_code == 200:
                break
        except httpx.TransportError:
            time.sleep(0.1)
    return process, client_port, log


def _routes_of(cluster: NatsCluster, index: int) -> int:
    """How many routes server ``index`` has (its cluster's others, and any rogue)."""
    routez = httpx.get(f"http://{HOST}:{cluster.monitor_ports[index]}/routez", timeout=5).json()
    return int(routez["num_routes"])


async def _rogue_touches_arrive(cluster: NatsCluster, rogue_port: int, wait_s: float) -> int:
    """Touches the rogue's anonymous client publishes that the armband's node receives."""
    access = cluster.credentials("a1")
    node = await nats.connect(
        cluster.urls[1],
        user=access["PHANTOMTOUCH_FLEET_USER"],
        password=access["PHANTOMTOUCH_FLEET_PASSWORD"],
        allow_reconnect=False,
    )
    received: list[bytes] = []

    async def got(message: object) -> None:
        received.append(b"")

    await node.subscribe(subjects.touch("a1"), cb=got)
    await node.flush()
    rogue = await nats.connect(f"nats://{HOST}:{rogue_port}", allow_reconnect=False)
    try:
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and not received:
            await rogue.publish(subjects.touch("a1"), b'{"touch": {"preset": "vr/tap"}}')
            await rogue.flush()
            await asyncio.sleep(0.2)
    finally:
        await rogue.close()
        await node.close()
    return len(received)


@pytest.mark.parametrize("open_routes", [False, True], ids=["closed", "open"])
def test_a_rogue_server_without_credentials_cannot_join(tmp_path: Path, open_routes: bool) -> None:
    with NatsCluster(
        tmp_path / "nats", size=2, jetstream=False, users=_users(), open_routes=open_routes
    ) as cluster:
        deadline = time.monotonic() + ROGUE_TRIES_S
        while time.monotonic() < deadline and not (
            _routes_of(cluster, 0) and _routes_of(cluster, 1)
        ):
            time.sleep(0.1)
        assert _routes_of(cluster, 0), "the cluster's own servers did not route to each other"
        rogue, rogue_port, log = _rogue(tmp_path, cluster)
        try:
            if not open_routes:  # until the cluster has refused the rogue's route at least once
                while (
                    time.monotonic() < deadline
                    and "authentication failure" not in cluster.log(0).lower()
                ):
                    time.sleep(0.1)
                assert "authentication failure" in cluster.log(0).lower(), cluster.log(0)
            arrived = asyncio.run(
                _rogue_touches_arrive(
                    cluster, rogue_port, 3.0 if not open_routes else ROGUE_TRIES_S
                )
            )
            joined = _routes_of(cluster, 0) > cluster.size - 1
        finally:
            rogue.terminate()
            rogue.wait(10)
    if open_routes:
        assert joined and arrived > 0, "the open cluster let no rogue in: the test sees nothing"
    else:
        assert not joined and arrived == 0, log.read_text()[-2000:]


def test_the_probe_refuses_open_route_ports_in_one_line(tmp_path: Path) -> None:
    with NatsCluster(
        tmp_path / "nats", size=2, jetstream=False, users=_users(), open_routes=True
    ) as cluster:
        argv = [sys.executable, "-m", "phantomtouch", "gateway", "--fleet", cluster.servers]
        argv += ["--fleet-routes", cluster.route_ports, "--host", HOST, "--port", str(free_port())]
        done = subprocess.run(
            argv,
            env={**os.environ, **cluster.credentials("gw0")},
            capture_output=True,
            text=True,
            timeout=60,
        )
        with pytest.raises(ParameterError, match="admits a server without credentials"):
            check_routes(cluster.urls, cluster.route_ports.split(","), "--insecure-nats")
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "route port" in lines[0] and "--insecure-nats" in lines[0]


def test_the_probe_passes_closed_routes_and_says_when_it_cannot_tell(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=2, jetstream=False, users=_users()) as cluster:
        assert check_routes(cluster.urls, cluster.route_ports.split(","), "--x") is None
        unnamed = check_routes(cluster.urls, [], "--x")
        assert unnamed is not None and "cannot tell" in unnamed and "--fleet-routes" in unnamed
        silent = f"{HOST}:{free_port()}"
        note = check_routes(cluster.urls, [silent], "--x")
        assert note is not None and "cannot tell" in note and silent in note
