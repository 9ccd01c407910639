"""``scripts/fleet`` starts a whole fleet and stops it quietly: the armbands and gateways
leave before NATS does, so none of them logs a lost NATS server.

The real script runs from a copy of ``scripts/`` whose ``.venv/bin/phantomtouch`` runs
this checkout's package with this interpreter; its NATS servers are real.
"""

from __future__ import annotations

import contextlib
import random
import signal
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests.support.live_server import HOST
from tests.support.nats_cluster import require_nats_server

ROOT = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 180.0
"""A wait for the fleet's armbands to come online on a busy machine, not a bound."""


def consecutive_free_ports(count: int) -> int:
    """The first of ``count`` consecutive ports that are free on :data:`HOST` now."""
    for _ in range(1000):
        first = random.randint(20_000, 60_000 - count)
        with contextlib.ExitStack() as stack:
            try:
                for port in range(first, first + count):
                    sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
                    sock.bind((HOST, port))
            except OSError:
                continue
            return first
    raise RuntimeError(f"no {count} consecutive free ports on {HOST}")


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    if sys.platform == "win32":
        pytest.skip("scripts/fleet is a bash script")
    require_nats_server()
    root = tmp_path / "repo"
    (root / "scripts").mkdir(parents=True)
    (root / "scripts" / "fleet").write_bytes((ROOT / "scripts" / "fleet").read_bytes())
    (root / "scripts" / "fleet").chmod(0o755)
    command = root / ".venv" / "bin" / "phantomtouch"
    command.parent.mkdir(parents=True)
    command.write_text(
        f'#!/bin/sh\nPYTHONPATH="{ROOT}" exec "{sys.executable}" -m phantomtouch "$@"\n'
    )
    command.chmod(command.stat().st_mode | stat.S_IXUSR)
    return root


def test_the_fleet_starts_and_stops_without_a_warning(checkout: Path) -> None:
    first = consecutive_free_ports(11)
    nats, route, node, gateway = first, first + 3, first + 6, first + 9
    run = checkout / "fleet-run"
    fleet = subprocess.Popen(
        [
            str(checkout / "scripts" / "fleet"),
            *("--nats-port", str(nats), "--route-port", str(route)),
            *("--node-port", str(node), "--gateway-port", str(gateway), str(run)),
        ],
        cwd=checkout,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        online: list[str] = []
        while time.monotonic() < deadline and len(online) < 3:
            assert fleet.poll() is None, fleet.communicate()[0]
            with contextlib.suppress(httpx.HTTPError, ValueError):
                answer = httpx.get(f"http://{HOST}:{gateway}/armbands", timeout=2.0)
                online = [a["armband"] for a in answer.json()]
            time.sleep(0.5)
        assert sorted(online) == ["a1", "a2", "a3"], online
    finally:
        fleet.send_signal(signal.SIGTERM)
        output = fleet.communicate(timeout=120)[0]
    assert fleet.returncode == 0, output
    logs = {path.name: path.read_text() for path in run.glob("*.log")}
    services = {n: t for n, t in logs.items() if not n.startswith("nats-")}
    assert len(services) == 5, sorted(logs)
    for name, text in services.items():
        assert "Finished server process" in text, f"{name} did not stop:\n{text}"
        warnings = [line for line in text.splitlines() if line.startswith(("WARNING", "ERROR"))]
        assert not warnings, f"{name}: {warnings}"
    assert "Traceback" not in output
