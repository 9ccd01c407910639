"""The real processes of each input of the attack table, each with the band captured.

- ``ws``, ``rest``, ``osc``: ``phantomtouch serve --osc 127.0.0.1:PORT`` (with the two
  patterns an OSC sender plays by name stored beforehand);
- ``bhaptics``: ``phantomtouch serve --bhaptics 127.0.0.1:PORT``;
- ``fleet``: a NATS server, an armband node (``serve --fleet``) and a gateway; the node's
  band is captured and its ``/stop`` is the stop.
"""

from __future__ import annotations

import json
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
from websockets.sync.client import connect

from phantomtouch.fleet.nats_config import plan
from tests.attacks.inputs import BIG_POINTS, SCORE_S, OscSource, polyline
from tests.bhaptics.test_standin_live import RELEASE_S, Capture
from tests.support.fleet import ArmbandNode, Gateway
from tests.support.live_server import HOST, LiveServer, free_port
from tests.support.nats_cluster import NatsCluster


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((HOST, 0))
        return int(probe.getsockname()[1])


@dataclass
class Stand:
    """The processes of one input; :meth:`stop` returns the band's capture."""

    server: LiveServer
    """The process that drives the band (for fleet: the armband node)."""
    wav: Path
    target: str
    """What the input's clients connect to (:mod:`tests.attacks.inputs`)."""
    others: list[Any] = field(default_factory=list)
    """Processes stopped after the server (gateway, NATS), in order."""

    def __post_init__(self) -> None:
        self.device = httpx.get(f"{self.url}/device", timeout=10.0).json()
        self.clocks: list[dict[str, Any]] = []
        self.read_clock()

    def read_clock(self) -> dict[str, Any]:
        """``GET /clock``: the engine's frame count at a server time (this machine's
        ``time.monotonic()``); the capture places spans by every clock read
        (:mod:`tests.support.clocks`)."""
        asked_s = time.monotonic()
        clock: dict[str, Any] = httpx.get(f"{self.url}/clock", timeout=10.0).json()
        answered_s = time.monotonic()
        if not asked_s - 1.0 < clock["server_time_s"] < answered_s + 1.0:
            # a fleet node keeps the fleet's clock: place its frame count on this machine's
            clock["server_time_s"] = (asked_s + answered_s) / 2
        self.clocks.append(clock)
        return clock

    @property
    def url(self) -> str:
        return self.server.url

    @property
    def ws_url(self) -> str:
        return self.server.ws_url

    @property
    def ceiling(self) -> float:
        """The band's ceiling, full scale."""
        return float(self.device.get("safety", {}).get("ceiling", 1.0))

    @property
    def after_stop_s(self) -> float:
        """A stopped touch is silent this long after the stop: the next block, the release."""
        return 2 * self.device["block_frames"] / self.device["sample_rate_hz"] + RELEASE_S

    def stop(self) -> Capture:
        for process in self.others:
            process.stop()
        self.server.stop()
        return Capture(self.wav, self.clocks, self.device)


def wait_for_armband(ws_url: str, armband: str, timeout_s: float = 60.0) -> None:
    """Until the gateway's ``welcome`` lists ``armband`` (its node's heartbeat reached it)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        with connect(ws_url) as ws:
            ws.send(json.dumps({"type": "hello", "id": 1}))
            if armband in json.loads(ws.recv(timeout=10.0)).get("armbands", []):
                return
        time.sleep(0.25)
    raise AssertionError(f"the gateway never saw armband {armband!r}")


def start_stand(kind: str, folder: Path) -> Stand:
    """Start the processes of input ``kind`` in ``folder``."""
    wav = folder / "band.wav"
    capture = f"capture:{wav}"
    if kind == "bhaptics":
        port = free_port()
        server = LiveServer(
            folder / "p.db", output=capture, args=("--bhaptics", f"{HOST}:{port}")
        ).start()
        return Stand(server, wav, f"ws://{HOST}:{port}/v2/feedbacks")
    if kind == "fleet":
        # Closed (phantomtouch fleet-config's users): only there does a node believe the
        # principal the gateway names for each of its clients (docs/fleet.md, "Who a client
        # is").
        users = plan([("a1", "lab")], ["gateway"])
        cluster = NatsCluster(folder / "nats", size=1, users=users).start()
        # The node's deadline is the one the gateway announces in its welcome (2 s), which
        # its clients keep to.
        deadline = {"PHANTOMTOUCH_WATCHDOG_S": "2.0"}
        node = ArmbandNode(folder, cluster, "a1", "lab", env=deadline, output=capture)
        node.start()
        gateway = Gateway(folder, cluster).start()
        wait_for_armband(gateway.ws_url, "a1")
        return Stand(node, wav, f"{gateway.ws_url} a1", others=[gateway, cluster])
    osc_port = free_udp_port()
    server = LiveServer(
        folder / "p.db", output=capture, args=("--osc", f"{HOST}:{osc_port}")
    ).start()
    big, long = OscSource.STORED
    for name, pattern in ((big, polyline(BIG_POINTS, 8.0)), (long, polyline(20, SCORE_S))):
        answer = httpx.put(f"{server.url}/patterns/{name}", json=pattern, timeout=60.0)
        answer.raise_for_status()
    target = {"ws": server.ws_url, "rest": server.url, "osc": f"{HOST}:{osc_port}"}[kind]
    return Stand(server, wav, target)
