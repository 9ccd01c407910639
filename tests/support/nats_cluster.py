"""A real NATS cluster (``nats-server``, JetStream on) on loopback ports, for tests.

Three servers by default, each with its own store folder, client port, cluster port and
monitoring port, all on 127.0.0.1. JetStream may be left off (a server with no registry);
``users`` closes the cluster with the configuration ``phantomtouch fleet-config`` writes,
its route ports included (``open_routes`` leaves those open, as a cluster built before
route authorization was).
:meth:`NatsCluster.kill` ends one with SIGKILL, as in a crash, and
:meth:`NatsCluster.restart` brings it back. Missing ``nats-server`` fails the test under
``CI=true`` and skips it elsewhere (:func:`require_nats_server`).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from phantomtouch.fleet.nats_config import FleetUser, RouteUser, authorization
from tests.support.live_server import HOST, free_ports

START_TIMEOUT_S = 20.0


def nats_server_path() -> str | None:
    return shutil.which("nats-server") or (
        "/usr/sbin/nats-server" if Path("/usr/sbin/nats-server").exists() else None
    )


def require_nats_server() -> str:
    """The ``nats-server`` binary; skip the test without it, or fail it under CI."""
    path = nats_server_path()
    if path is None:
        reason = "nats-server not found (Debian package nats-server, scripts/apt-packages.txt)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"a real NATS server is required under CI: {reason}")
        pytest.skip(reason)
    return path


class NatsCluster:
    """``size`` clustered ``nats-server`` processes with JetStream, in ``folder``."""

    def __init__(
        self,
        folder: Path,
        *,
        size: int = 3,
        user: str | None = None,
        password: str | None = None,
        jetstream: bool = True,
        users: list[FleetUser] | None = None,
        open_routes: bool = False,
    ) -> None:
        self.binary = require_nats_server()
        self.folder = folder
        self.size = size
        self.jetstream = jetstream
        self.users = {user.name: user for user in users or []}
        self.route = RouteUser.new() if users and not open_routes else None
        """The route user of a closed cluster (None: its route ports admit anyone)."""
        self.user = user
        self.password = password
        ports = free_ports(3 * size)
        self.client_ports = ports[:size]
        self.cluster_ports = ports[size : 2 * size]
        self.monitor_ports = ports[2 * size :]
        self.processes: list[subprocess.Popen[bytes] | None] = [None] * size
        folder.mkdir(parents=True, exist_ok=True)

    @property
    def urls(self) -> list[str]:
        return [f"nats://{HOST}:{port}" for port in self.client_ports]

    @property
    def secured(self) -> bool:
        """Whether the cluster runs the closed configuration of ``phantomtouch fleet-config``."""
        return bool(self.users)

    def credentials(self, name: str) -> dict[str, str]:
        """The environment of user ``name`` of the closed configuration."""
        user = self.users[name]
        return {"PHANTOMTOUCH_FLEET_USER": user.name, "PHANTOMTOUCH_FLEET_PASSWORD": user.password}

    @property
    def route_ports(self) -> str:
        """The route ports as ``--fleet-routes`` takes them."""
        return ",".join(f"{HOST}:{port}" for port in self.cluster_ports)

    @property
    def servers(self) -> str:
        """The URLs as ``--fleet`` takes them."""
        return ",".join(self.urls)

    def _config(self, index: int) -> Path:
        routes = ", ".join(
            self.route.route_url(HOST, port) if self.route else f"nats-route://{HOST}:{port}"
            for i, port in enumerate(self.cluster_ports)
            if i != index
        )
        store = self.folder / f"n{index}"
        store.mkdir(parents=True, exist_ok=True)
        config = self.folder / f"n{index}.conf"
        text = f"""
server_name: n{index}
listen: {HOST}:{self.client_ports[index]}
http: {HOST}:{self.monitor_ports[index]}
"""
        if self.jetstream:
            text += f"""
jetstream {{
  store_dir: "{store}"
  max_memory_store: 64MB
  max_file_store: 256MB
}}
"""
        if self.size > 1:
            text += f"""
cluster {{
  name: phantomtouch-test
  listen: {HOST}:{self.cluster_ports[index]}
  routes: [{routes}]
  {self.route.authorization() if self.route else ""}
}}
"""
        if self.user is not None:
            text += f'authorization {{ user: "{self.user}", password: "{self.password}" }}\n'
        if self.users:
            text += authorization(list(self.users.values()))
        config.write_text(text)
        return config

    def _launch(self, index: int) -> None:
        log = (self.folder / f"n{index}.log").open("ab")
        self.processes[index] = subprocess.Popen(
            [self.binary, "-c", str(self._config(index))], stdout=log, stderr=subprocess.STDOUT
        )
        log.close()

    def start(self) -> NatsCluster:
        for index in range(self.size):
            self._launch(index)
        self.wait_ready(range(self.size))
        return self

    def wait_ready(self, indexes: range | list[int]) -> None:
        """Until each server's ``/healthz`` says JetStream is ready."""
        deadline = time.monotonic() + START_TIMEOUT_S
        pending = list(indexes)
        while pending and time.monotonic() < deadline:
            index = pending[0]
            process = self.processes[index]
            assert process is not None
            if process.poll() is not None:
                raise RuntimeError(f"nats-server n{index} exited:\n{self.log(index)}")
            try:
                url = f"http://{HOST}:{self.monitor_ports[index]}/healthz"
                if httpx.get(url, timeout=1.0).status_code == 200:
                    pending.pop(0)
                    continue
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        if pending:
            raise RuntimeError(f"nats-server n{pending[0]} not ready:\n{self.log(pending[0])}")

    def log(self, index: int) -> str:
        path = self.folder / f"n{index}.log"
        return path.read_text(errors="replace")[-3000:] if path.exists() else ""

    def kill(self, index: int) -> None:
        """SIGKILL one server (a crash)."""
        process = self.processes[index]
        if process is not None and process.poll() is None:
            process.kill()
            process.wait()
        self.processes[index] = None

    def restart(self, index: int) -> None:
        self.kill(index)
        self._launch(index)
        self.wait_ready([index])

    def stop(self) -> None:
        for index, process in enumerate(self.processes):
            if process is not None and process.poll() is None:
                process.terminate()
                try:
                    process.wait(10)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            self.processes[index] = None

    def __enter__(self) -> NatsCluster:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
