"""Caps on WebSocket connections: remote addresses are refused (1013), loopback never.

The server listens on every interface (with a token, as it must off loopback); the test
reaches it through this machine's own non-loopback address, which the server sees as a
remote client, and through 127.0.0.1.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import socket
from collections.abc import Iterator

import httpx
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from phantomtouch.service.errors import WS_CLOSE_TRY_AGAIN_LATER
from tests.support.live_server import LiveServer

TOKEN = "fair-shares-token-0123456789"
TOTAL = 64
PER_ADDRESS = 16


def own_address() -> str | None:
    """This machine's address on its default route (not loopback), or None."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # no datagram is sent
        except OSError:
            return None
        address = str(probe.getsockname()[0])
    return None if address.startswith("127.") else address


@pytest.fixture(scope="module")
def remote_host() -> str:
    address = own_address()
    if address is None:
        if os.environ.get("CI") == "true":
            pytest.fail("this machine has no non-loopback address to connect from")
        pytest.skip("this machine has no non-loopback address to connect from")
    return address


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory, remote_host: str) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("caps")
    env = {"PHANTOMTOUCH_TOKEN": TOKEN}
    with LiveServer(folder / "patterns.db", env=env, args=("--host", "0.0.0.0")) as server:
        yield server


def url(live: LiveServer, host: str) -> str:
    return f"ws://{host}:{live.port}/ws?token={TOKEN}"


async def welcomed(ws: ClientConnection) -> bool:
    await ws.send(json.dumps({"type": "hello", "id": 1}))
    return bool(json.loads(await asyncio.wait_for(ws.recv(), 5))["type"] == "welcome")


async def refused(address: str) -> tuple[int | None, str]:
    """Connect and wait for the server to close: its close code and reason."""
    async with connect(address) as ws:
        with pytest.raises(ConnectionClosed) as closed:
            await asyncio.wait_for(ws.recv(), 5)
    received = closed.value.rcvd
    return (None, "") if received is None else (received.code, received.reason)


def refusals(live: LiveServer) -> dict[str, float]:
    text = httpx.get(f"{live.url}/metrics", headers={"Authorization": f"Bearer {TOKEN}"}).text
    found = {}
    for line in text.splitlines():
        match = re.match(r'^phantomtouch_ws_refused_connections_total\{cap="(\w+)"\} (\S+)$', line)
        if match:
            found[match.group(1)] = float(match.group(2))
        if line.startswith("phantomtouch_ws_open_connections "):
            found["open"] = float(line.split()[1])
    return found


def test_remote_connections_are_capped_and_loopback_never(
    live: LiveServer, remote_host: str
) -> None:
    async def scenario() -> None:
        async with contextlib.AsyncExitStack() as stack:
            remote = [
                await stack.enter_async_context(connect(url(live, remote_host)))
                for _ in range(PER_ADDRESS)
            ]
            assert all([await welcomed(ws) for ws in remote])
            code, reason = await refused(url(live, remote_host))
            assert code == WS_CLOSE_TRY_AGAIN_LATER
            assert f"max_ws_connections_per_address={PER_ADDRESS}" in reason
            for ws in remote[4:]:
                await ws.close()
            local = [
                await stack.enter_async_context(connect(url(live, "127.0.0.1")))
                for _ in range(TOTAL - 4)
            ]
            assert await welcomed(local[-1])
            code, reason = await refused(url(live, remote_host))  # the 65th, from afar
            assert code == WS_CLOSE_TRY_AGAIN_LATER
            assert f"max_ws_connections={TOTAL}" in reason
            for _ in range(4):  # loopback is never locked out
                extra = await stack.enter_async_context(connect(url(live, "127.0.0.1")))
                assert await welcomed(extra)
            assert refusals(live) == {"total": 1.0, "per_address": 1.0, "open": TOTAL + 4.0}

    asyncio.run(scenario())
