"""A whole fleet on one machine for tests: NATS cluster, armband nodes and gateways.

Armband nodes are real ``phantomtouch serve --fleet`` processes on the null output; each
keeps the engine's stimulus log (what it played, from which frame, at which time) in the
test's folder, which is how a test sees what reached which armband. Gateways are real
``phantomtouch gateway`` processes. Everything listens on 127.0.0.1. On a cluster that runs
the closed configuration each starts with its own user's credentials; on an open one with
the flag that accepts it (``--fleet-insecure``, ``--insecure-nats``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

from tests.support.live_server import HOST, LiveServer, free_port
from tests.support.nats_cluster import NatsCluster

HEARTBEAT_S = 0.25
TTL_S = 1.5
WATCHDOG_S = 0.5
NODE_ENV = {
    "PHANTOMTOUCH_ENGINE_PROCESS": "false",
    "PHANTOMTOUCH_FLEET_HEARTBEAT_S": str(HEARTBEAT_S),
    "PHANTOMTOUCH_FLEET_TTL_S": str(TTL_S),
    "PHANTOMTOUCH_WATCHDOG_S": str(WATCHDOG_S),
}
"""Short heartbeats, TTL and watchdog keep the tests short; the engine runs in a thread of
each node (three engine processes more would only load the machine's two cores)."""


class ArmbandNode(LiveServer):
    """``phantomtouch serve --fleet ... --armband ID --site SITE`` with a stimulus log
    (``servers``: the ``--fleet`` URLs, when not every server of the cluster)."""

    def __init__(
        self,
        folder: Path,
        cluster: NatsCluster,
        armband: str,
        site: str,
        env: dict[str, str] | None = None,
        output: str = "null",
        servers: str | None = None,
    ) -> None:
        self.armband = armband
        self.site = site
        self.stimulus_log = folder / f"{armband}.jsonl"
        access = cluster.credentials(armband) if cluster.secured else {}
        insecure = () if cluster.secured else ("--fleet-insecure",)
        super().__init__(
            folder / f"{armband}.db",
            env={
                **NODE_ENV,
                **access,
                "PHANTOMTOUCH_ENGINE_LOG_PATH": str(self.stimulus_log),
                **(env or {}),
            },
            args=(
                *("--fleet", servers or cluster.servers),
                *("--armband", armband, "--site", site, *insecure),
            ),
            output=output,
        )

    def launch(self) -> subprocess.Popen[bytes]:
        """Start the process without waiting for it (:meth:`start` waits until healthy)."""
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                self.command(), env={**os.environ, **self.env}, stdout=log, stderr=subprocess.STDOUT
            )
        return self.process

    def played(self) -> list[dict[str, Any]]:
        """The ``start`` records of jobs in the stimulus log so far."""
        if not self.stimulus_log.exists():
            return []
        records = [json.loads(line) for line in self.stimulus_log.read_text().splitlines()]
        return [r for r in records if r["event"] == "start" and r["kind"] == "job"]

    def wait_played(self, job_id: str, timeout_s: float = 60.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for record in self.played():
                if record["job_id"] == job_id:
                    return record
            time.sleep(0.05)
        raise AssertionError(f"job {job_id} never started on armband {self.armband}")

    def metric(self, name: str, labels: str = "") -> float:
        """One sample of the node's ``/metrics`` (0 when absent)."""
        text = httpx.get(f"{self.url}/metrics", timeout=5.0).text
        prefix = f"{name}{{{labels}}}" if labels else name
        for line in text.splitlines():
            if line.startswith(prefix + " "):
                return float(line.split()[-1])
        return 0.0


class Gateway:
    """``phantomtouch gateway --fleet ...`` on a free port (``servers`` as for
    :class:`ArmbandNode`)."""

    def __init__(
        self,
        folder: Path,
        cluster: NatsCluster,
        env: dict[str, str] | None = None,
        name: str = "gateway",
        servers: str | None = None,
    ):
        self.port = free_port()
        self.cluster = cluster
        self.servers = servers or cluster.servers
        self.log_path = folder / f"gateway-{self.port}.log"
        access = cluster.credentials(name) if cluster.secured else {}
        self.env = {**access, **(env or {})}
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://{HOST}:{self.port}/ws"

    def launch(self) -> subprocess.Popen[bytes]:
        """Start the process without waiting for it (:meth:`start` waits until healthy)."""
        command = [sys.executable, "-m", "phantomtouch", "gateway", "--fleet"]
        command += [self.servers, "--port", str(self.port)]
        if not self.cluster.secured:
            command.append("--insecure-nats")
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                command, env={**os.environ, **self.env}, stdout=log, stderr=subprocess.STDOUT
            )
        return self.process

    def start(self) -> Gateway:
        self.process = self.launch()
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"gateway exited:\n{self.log()}")
            try:
                if httpx.get(f"{self.url}/health", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        raise RuntimeError(f"gateway not healthy:\n{self.log()}")

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")[-3000:]

    def kill(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()
