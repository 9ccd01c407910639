"""Closed by default: NATS itself refuses anonymous clients and a node reaching past its
armband; ``serve --fleet`` and ``gateway`` refuse a NATS server open to anonymous
publishers unless told they may.

The module's fleet (tests/fleet/conftest.py) runs the configuration that
``phantomtouch fleet-config`` writes.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import nats
import pytest

from phantomtouch.fleet.nats_config import inbox_prefix
from tests.fleet.conftest import Fleet
from tests.support.live_server import HOST, free_port
from tests.support.nats_cluster import NatsCluster


async def _as_node(url: str, access: dict[str, str]) -> tuple[Any, list[str]]:
    refused: list[str] = []

    async def error(exc: Exception) -> None:
        refused.append(str(exc))

    user = access["PHANTOMTOUCH_FLEET_USER"]
    nc = await nats.connect(
        url,
        user=user,
        password=access["PHANTOMTOUCH_FLEET_PASSWORD"],
        inbox_prefix=inbox_prefix(user),
        error_cb=error,
        allow_reconnect=False,
    )
    return nc, refused


async def _reach_past(url: str, access: dict[str, str]) -> list[str]:
    nc, refused = await _as_node(url, access)
    try:
        await nc.publish("phantomtouch.armband.a2.touch", b'{"touch": {"preset": "vr/tap"}}')
        await nc.publish("phantomtouch.armband.a2.contact", b'{"type": "ping", "owner": "x"}')
        await nc.publish("phantomtouch.armband.a1.touch", b'{"touch": {"preset": "vr/tap"}}')
        await nc.publish("$KV.phantomtouch_armbands.a2", b"{}")
        await nc.publish("phantomtouch.released.a2.gw-x-1", b'{"contacts": [], "reason": "x"}')
        await nc.subscribe("phantomtouch.armband.a2.touch")
        await nc.flush()
        for _ in range(50):
            if len(refused) >= 6:
                break
            await asyncio.sleep(0.05)
        return refused
    finally:
        await nc.close()


def test_an_anonymous_client_is_refused_by_nats(fleet: Fleet) -> None:
    async def anonymous() -> None:
        nc = await nats.connect(fleet.cluster.urls[0], allow_reconnect=False)
        await nc.close()

    with pytest.raises(Exception, match=r"(?i)authorization violation"):
        asyncio.run(anonymous())


def test_a_node_cannot_publish_on_another_armbands_subjects(fleet: Fleet) -> None:
    before = fleet.nodes["a2"].metric("phantomtouch_fleet_messages_total")
    refused = asyncio.run(_reach_past(fleet.cluster.urls[1], fleet.cluster.credentials("a1")))
    text = "\n".join(refused).lower()
    for subject in (
        'publish to "phantomtouch.armband.a2.touch"',
        'publish to "phantomtouch.armband.a2.contact"',
        'publish to "phantomtouch.armband.a1.touch"',
        'publish to "$kv.phantomtouch_armbands.a2"',
        'publish to "phantomtouch.released.a2.gw-x-1"',
        'subscription to "phantomtouch.armband.a2.touch"',
    ):
        assert f"permissions violation for {subject}" in text, refused
    assert fleet.nodes["a2"].metric("phantomtouch_fleet_messages_total") == before


@pytest.mark.parametrize(
    ("command", "flag"),
    [
        (["serve", "--output", "null", "--armband", "x1"], "--fleet-insecure"),
        (["gateway"], "--insecure-nats"),
    ],
)
def test_an_open_nats_server_is_refused_in_one_line(
    tmp_path: Path, command: list[str], flag: str
) -> None:
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        argv = [sys.executable, "-m", "phantomtouch", *command, "--fleet", cluster.servers]
        argv += ["--host", HOST, "--port", str(free_port())]
        if command[0] == "serve":
            argv += ["--db", str(tmp_path / "a.db")]
        done = subprocess.run(
            argv,
            env={**os.environ, "PHANTOMTOUCH_ENGINE_PROCESS": "false"},
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "lets a client without credentials publish" in lines[0]
    assert flag in lines[0]
