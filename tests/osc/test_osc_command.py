"""``phantomtouch serve --osc``: the command line attaches the OSC bridge to the service.

The server itself knows nothing of OSC (docs/architecture.md); a real ``serve`` process
must still receive OSC on the address it is given, count it in ``/metrics`` and close the
bridge when it stops.
"""

from __future__ import annotations

import re
import socket
import time
from pathlib import Path

import httpx
from pythonosc.udp_client import SimpleUDPClient

from tests.support.live_server import HOST, LiveServer

WAIT_S = 10.0


def accepted(url: str) -> float:
    """The bridge's ``accepted`` count in ``/metrics`` (0 before the first message)."""
    text = httpx.get(f"{url}/metrics", timeout=5.0).text
    found = re.search(r'^phantomtouch_osc_messages_total\{outcome="accepted"\} (\S+)$', text, re.M)
    return float(found[1]) if found else 0.0


def wait_accepted(url: str, count: float) -> float:
    deadline = time.monotonic() + WAIT_S
    while (seen := accepted(url)) < count and time.monotonic() < deadline:
        time.sleep(0.05)
    return seen


def test_serve_with_osc_receives_counts_and_closes_the_bridge(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((HOST, 0))
        udp_port = int(probe.getsockname()[1])
    server = LiveServer(tmp_path / "p.db", args=("--osc", f"{HOST}:{udp_port}"))
    with server:
        osc = SimpleUDPClient(HOST, udp_port)
        osc.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 0.5])
        assert wait_accepted(server.url, 1.0) == 1.0, server.log()
        osc.send_message("/phantomtouch/stop", [])
        assert wait_accepted(server.url, 2.0) == 2.0, server.log()
    log = server.log()
    assert f"OSC on udp://{HOST}:{udp_port}" in log
    assert "Application shutdown complete" in log and "Traceback" not in log, log
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as again:
        again.bind((HOST, udp_port))  # the bridge let go of its address


def test_serve_without_osc_attaches_no_bridge(tmp_path: Path) -> None:
    with LiveServer(tmp_path / "p.db") as server:
        metrics = httpx.get(f"{server.url}/metrics", timeout=5.0).text
    assert "phantomtouch_osc_messages" not in metrics
    assert "OSC on udp" not in server.log()
