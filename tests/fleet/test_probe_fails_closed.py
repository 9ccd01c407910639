"""Fail closed: the anonymous probe that cannot decide retries, then refuses to start
(exit 2, with the reason); it never takes a server it could not judge as closed.

A TCP proxy in front of a real, open ``nats-server`` stalls the first connections it is
given (the server is slow for the first connection only): before, the probe timed out,
took the cluster as closed and the node joined an open NATS."""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from phantomtouch.errors import ParameterError
from phantomtouch.fleet.openness import anonymous_can_publish
from tests.support.live_server import HOST, free_port
from tests.support.nats_cluster import NatsCluster


class StallingProxy:
    """Forwards TCP connections to ``target``, but holds the first ``stalled`` ones open
    without a byte forwarded until the proxy closes."""

    def __init__(self, target: tuple[str, int], stalled: int) -> None:
        self.target = target
        self.stalled = stalled
        self.accepted = 0
        self._listener = socket.create_server((HOST, 0))
        self._closing = threading.Event()
        self._held: list[socket.socket] = []
        self._thread = threading.Thread(target=self._serve, daemon=True)

    @property
    def url(self) -> str:
        return f"nats://{HOST}:{self._listener.getsockname()[1]}"

    def _serve(self) -> None:
        self._listener.settimeout(0.1)
        while not self._closing.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            self.accepted += 1
            if self.accepted <= self.stalled:
                self._held.append(client)
                continue
            upstream = socket.create_connection(self.target)
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pipe, args=(a, b), daemon=True).start()

    @staticmethod
    def _pipe(source: socket.socket, sink: socket.socket) -> None:
        with contextlib.suppress(OSError):
            while data := source.recv(65536):
                sink.sendall(data)
        with contextlib.suppress(OSError):
            sink.shutdown(socket.SHUT_WR)

    def __enter__(self) -> StallingProxy:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._closing.set()
        self._thread.join()
        for held in self._held:
            held.close()
        self._listener.close()


@pytest.fixture
def open_nats(tmp_path: Path) -> Iterator[NatsCluster]:
    with NatsCluster(tmp_path / "nats", size=1, jetstream=False) as cluster:
        yield cluster


def test_a_probe_whose_first_connection_stalls_tries_again_and_finds_the_server_open(
    open_nats: NatsCluster,
) -> None:
    with StallingProxy((HOST, open_nats.client_ports[0]), stalled=1) as proxy:
        assert asyncio.run(anonymous_can_publish([proxy.url], timeout_s=0.5)) is True
        assert proxy.accepted >= 2


def test_a_probe_that_never_decides_refuses_naming_why(open_nats: NatsCluster) -> None:
    with (
        StallingProxy((HOST, open_nats.client_ports[0]), stalled=1000) as proxy,
        pytest.raises(ParameterError, match=r"could not tell .* \(3 tries; the last: "),
    ):
        asyncio.run(anonymous_can_publish([proxy.url], timeout_s=0.3))


def test_a_node_whose_probe_stalls_first_refuses_the_open_server_and_exits_2(
    tmp_path: Path, open_nats: NatsCluster
) -> None:
    with StallingProxy((HOST, open_nats.client_ports[0]), stalled=1) as proxy:
        argv = [sys.executable, "-m", "phantomtouch", "serve", "--output", "null"]
        argv += ["--armband", "x1", "--fleet", proxy.url, "--db", str(tmp_path / "a.db")]
        argv += ["--host", HOST, "--port", str(free_port())]
        done = subprocess.run(
            argv,
            env={**os.environ, "PHANTOMTOUCH_ENGINE_PROCESS": "false"},
            capture_output=True,
            text=True,
            timeout=90,
        )
    assert done.returncode == 2, done.stdout + done.stderr
    assert "lets a client without credentials publish" in done.stderr.strip().splitlines()[-1]
