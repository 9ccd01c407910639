"""A start that cannot finish ends at its deadline: no step waits past it.

Against a real NATS server: one stopped (SIGSTOP) after the node opened the registry, so
the node's next call waits on a request that never comes back; and a registry watch whose
"caught up" marker is lost while the nodes' heartbeats keep arriving, as a gateway's
first read met it (tests/fleet/test_startup.py then waited for it for ever).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from phantomtouch.fleet.errors import FleetJoinError
from phantomtouch.fleet.registry_view import RegistryView
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, announce, open_registry
from tests.support.fleet_startup import HEARTBEAT_S, TTL_S, record
from tests.support.nats_cluster import NatsCluster

REQUEST_TIMEOUT_S = 30.0
"""Each NATS request's own timeout, far beyond the start deadlines below, s."""
STOPPED_DEADLINE_S = 1.0
FIRST_READ_DEADLINE_S = 10.0
NODES = ["s1", "s2", "s3"]


async def _watch_while_the_server_is_stopped(cluster: NatsCluster) -> tuple[str, float]:
    """The node's error, and how long its start waited for it (s)."""
    settings = FleetSettings(servers=cluster.urls, request_timeout_s=REQUEST_TIMEOUT_S)
    nc, kv = await open_registry(settings, "armband-x1", Deadline(settings.start_deadline_s))

    async def beat() -> None:
        await kv.put("x1", record("x1"))

    process = cluster.processes[0]
    assert process is not None
    os.kill(process.pid, signal.SIGSTOP)
    try:
        started_s = time.monotonic()
        with pytest.raises(FleetJoinError) as failed:
            await announce(kv, "x1", beat, Deadline(STOPPED_DEADLINE_S))
        waited_s = time.monotonic() - started_s
    finally:
        os.kill(process.pid, signal.SIGCONT)
        await nc.close()
    return str(failed.value), waited_s


def test_a_step_waiting_on_a_server_that_stopped_answering_ends_at_the_deadline(
    tmp_path: Path,
) -> None:
    if sys.platform == "win32":
        pytest.skip("SIGSTOP is POSIX")
    with NatsCluster(tmp_path / "nats", size=1) as cluster:
        message, waited_s = asyncio.run(_watch_while_the_server_is_stopped(cluster))
    assert "\n" not in message
    assert message.startswith("fleet: armband 'x1' could not watch its registry key within 1 s")
    assert "still waiting" in message
    assert waited_s < REQUEST_TIMEOUT_S


class _Uncaught:
    """A real registry watch whose "caught up" marker never arrives."""

    def __init__(self, watcher: Any) -> None:
        self.watcher = watcher

    async def updates(self, timeout: float) -> Any:
        while True:
            entry = await self.watcher.updates(timeout=timeout)
            if entry is not None:
                return entry

    async def stop(self) -> None:
        await self.watcher.stop()


class _MarkerLost:
    """The real registry bucket, except that its watches lose their "caught up" marker."""

    def __init__(self, kv: Any) -> None:
        self.kv = kv

    async def status(self) -> Any:
        return await self.kv.status()

    async def watchall(self) -> _Uncaught:
        return _Uncaught(await self.kv.watchall())


async def _first_read_while_nodes_beat(cluster: NatsCluster) -> tuple[set[str], bool]:
    """What the gateway listed after its first read, and whether the nodes were still
    beating then (they stop after twice the start deadline, so that a start which waits
    for the marker ends)."""
    settings = FleetSettings(servers=cluster.urls, heartbeat_s=HEARTBEAT_S, ttl_s=TTL_S)
    nc, kv = await open_registry(settings, "gateway-test", Deadline(settings.start_deadline_s))

    written = asyncio.Event()

    async def beats() -> None:
        end_s = time.monotonic() + 2 * FIRST_READ_DEADLINE_S
        while time.monotonic() < end_s:
            for name in NODES:
                await kv.put(name, record(name))
            written.set()
            await asyncio.sleep(HEARTBEAT_S)

    beating = asyncio.create_task(beats())
    view = RegistryView(_MarkerLost(kv))
    try:
        await written.wait()
        await view.start("gateway test", Deadline(FIRST_READ_DEADLINE_S))
        return {r.armband for r in view.online()}, not beating.done()
    finally:
        await view.close()
        beating.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await beating
        await nc.close()


def test_a_first_read_whose_watch_never_says_caught_up_reads_the_registry(
    tmp_path: Path,
) -> None:
    with NatsCluster(tmp_path / "nats") as cluster:
        listed, beating = asyncio.run(_first_read_while_nodes_beat(cluster))
    assert listed == set(NODES)
    assert beating
