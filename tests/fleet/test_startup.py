"""Start-up without a race: nodes and gateways started at the same instant all register.

The 20 simultaneous starts run the fleet's start-up path (connect, open or create the
registry bucket, watch, first heartbeat; a gateway's first read of the registry) in four
processes at once against the real 3-server cluster, the bucket deleted before each
round (tests/support/fleet_startup.py says what that leaves out); one round starts the
real ``serve --fleet`` and ``gateway`` processes together. A node that cannot register
says why in one line and exits 1.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import httpx

from tests.support.fleet import ArmbandNode, Gateway
from tests.support.fleet_startup import run_rounds
from tests.support.live_server import HOST, free_port
from tests.support.nats_cluster import NatsCluster
from tests.support.waiting import wait_until

ROUNDS = 20


def test_three_nodes_and_a_gateway_started_together_register_every_time(
    tmp_path: Path,
) -> None:
    with NatsCluster(tmp_path / "nats") as cluster:
        outcomes = run_rounds(cluster.servers, ROUNDS, deadline_s=20.0)
    failed = [o for o in outcomes if o.outcome != "ok"]
    assert len(outcomes) == 4 * ROUNDS
    assert failed == []


def test_real_processes_started_at_the_same_instant_all_register(tmp_path: Path) -> None:
    """Launched together; each engine measures its render budget first, which takes long
    on a busy machine, so the bound here is generous: what counts is that none exits."""
    with NatsCluster(tmp_path / "nats") as cluster:
        nodes = [ArmbandNode(tmp_path, cluster, f"r{i}", "lab") for i in range(3)]
        gateway = Gateway(tmp_path, cluster)
        try:
            processes = [part.launch() for part in (*nodes, gateway)]

            def listed() -> set[str]:
                exited = [p.args for p in processes if p.poll() is not None]
                assert exited == [], "\n".join(part.log() for part in (*nodes, gateway))
                try:
                    answer = httpx.get(f"{gateway.url}/armbands", timeout=2.0)
                except httpx.TransportError:
                    return set()
                return {r["armband"] for r in answer.json()}

            wait_until(lambda: listed() == {"r0", "r1", "r2"}, 120.0, "all three listed")
        finally:
            gateway.stop()
            for node in nodes:
                node.stop()


def test_a_node_that_cannot_register_says_why_in_one_line_and_exits_1(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1, jetstream=False) as cluster:
        command = [sys.executable, "-m", "phantomtouch", "serve", "--output", "null"]
        command += ["--host", HOST, "--port", str(free_port()), "--db", str(tmp_path / "a.db")]
        command += ["--fleet", cluster.servers, "--armband", "x1", "--fleet-insecure"]
        env = {"PHANTOMTOUCH_FLEET_START_DEADLINE_S": "1", "PHANTOMTOUCH_ENGINE_PROCESS": "false"}
        done = subprocess.run(
            command, env={**os.environ, **env}, capture_output=True, text=True, timeout=60
        )
    assert done.returncode == 1, done.stderr
    errors = [line for line in done.stderr.splitlines() if "Traceback" in line]
    assert errors == []
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("phantomtouch serve: fleet: armband-x1 could not open the registry")
    assert "within 1 s" in last


def test_a_gateway_that_cannot_read_the_registry_exits_1(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats", size=1, jetstream=False) as cluster:
        command = [sys.executable, "-m", "phantomtouch", "gateway", "--fleet", cluster.servers]
        command += ["--port", str(free_port()), "--insecure-nats"]
        env = {"PHANTOMTOUCH_FLEET_START_DEADLINE_S": "1"}
        done = subprocess.run(
            command, env={**os.environ, **env}, capture_output=True, text=True, timeout=60
        )
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("phantomtouch gateway: fleet: gateway-")
    assert "could not open the registry within 1 s" in last
