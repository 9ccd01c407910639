"""Datagrams the kernel drops before the OSC bridge reads them are counted in ``/metrics``.

A real ``phantomtouch serve --osc`` is paused (SIGSTOP) while 20,000 datagrams of 1 KB
are sent to its OSC port: its receive buffer holds a few hundred, the kernel drops the
rest. Resumed, the bridge reads what was kept. On loopback a datagram is either read or
dropped by the kernel, so every one sent is counted exactly once: by the bridge (its
outcome) or as a kernel drop (``phantomtouch_osc_kernel_drops_total``).
"""

from __future__ import annotations

import os
import re
import signal
import socket
import sys
import time
from pathlib import Path

import httpx
import pytest
from pythonosc.osc_message_builder import OscMessageBuilder

from tests.support.live_server import LiveServer

SENT = 20_000


def datagram() -> bytes:
    builder = OscMessageBuilder("/unknown/address")
    builder.add_arg("x" * 1000)
    return builder.build().dgram


def counted(server: LiveServer) -> tuple[float, float]:
    """(messages the bridge counted, datagrams the kernel dropped)."""
    text = httpx.get(f"{server.url}/metrics", timeout=10).text
    bridge = sum(
        float(m) for m in re.findall(r"^phantomtouch_osc_messages_total\{.*\} (\S+)$", text, re.M)
    )
    drops = re.search(r"^phantomtouch_osc_kernel_drops_total (\S+)$", text, re.M)
    assert drops is not None, "no phantomtouch_osc_kernel_drops_total in /metrics"
    return bridge, float(drops.group(1))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the drop counter is Linux's")
def test_every_datagram_is_counted_read_or_dropped_by_the_kernel(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        osc_port = probe.getsockname()[1]
    env = {"XDG_RUNTIME_DIR": str(tmp_path)}
    with LiveServer(tmp_path / "p.db", args=("--osc", f"127.0.0.1:{osc_port}"), env=env) as server:
        assert server.process is not None
        assert counted(server) == (0.0, 0.0)
        payload = datagram()
        os.kill(server.process.pid, signal.SIGSTOP)
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
                for _ in range(SENT):
                    sender.sendto(payload, ("127.0.0.1", osc_port))
        finally:
            os.kill(server.process.pid, signal.SIGCONT)
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            bridge, drops = counted(server)
            if bridge + drops >= SENT:
                break
            time.sleep(0.2)
        assert drops > 0, "the kernel kept every datagram: nothing was dropped"
        assert bridge + drops == SENT, (bridge, drops)
