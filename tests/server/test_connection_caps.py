"""Connection slots of WebSocket connections: a remote newcomer past a cap takes the slot of
the connection of its address silent longest (closed 1013), loopback is never made to yield
nor refused, and a remote newcomer finding only loopback connections is refused 1013.

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


async def closed_by_server(ws: ClientConnection) -> tuple[int | None, str]:
    """Wait for the server to close ``ws``: its close code and reason."""
    with pytest.raises(ConnectionClosed) as closed:
        await asyncio.wait_for(ws.recv(), 5)
    received = closed.value.rcvd
    return (None, "") if received is None else (received.code, received.reason)


async def refused(address: str) -> tuple[int | None, str]:
    """Connect and wait for the server to close: its close code and reason."""
    async with connect(address) as ws:
        return await closed_by_server(ws)


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


def test_remote_newcomers_take_the_slot_silent_longest_and_loopback_never_yields(
    live: LiveServer, remote_host: str
) -> None:
    async def scenario() -> None:
        async with contextlib.AsyncExitStack() as stack:
            remote = [
                await stack.enter_async_context(connect(url(live, remote_host)))
                for _ in range(PER_ADDRESS)
            ]
            assert all([await welcomed(ws) for ws in remote[1:]])  # remote[0] silent longest
            newcomer = await stack.enter_async_context(connect(url(live, remote_host)))
            assert await welcomed(newcomer)
            code, reason = await closed_by_server(remote[0])
            assert code == WS_CLOSE_TRY_AGAIN_LATER and "made room for a newcomer" in reason
            local = [
                await stack.enter_async_context(connect(url(live, "127.0.0.1")))
                for _ in range(TOTAL - PER_ADDRESS)
            ]
            assert await welcomed(local[-1])  # all 64 slots taken
            late = await stack.enter_async_context(connect(url(live, remote_host)))
            assert await welcomed(late)  # the 65th, from afar: a remote one yields
            code, _ = await closed_by_server(remote[1])
            assert code == WS_CLOSE_TRY_AGAIN_LATER
            for _ in range(4):  # loopback is never locked out
                extra = await stack.enter_async_context(connect(url(live, "127.0.0.1")))
                assert await welcomed(extra)
            for ws in [*remote[2:], newcomer, late]:
                await ws.close()
            for _ in range(TOTAL - len(local) - 4):  # every slot held from loopback
                await stack.enter_async_context(connect(url(live, "127.0.0.1")))
            code, reason = await refused(url(live, remote_host))
            assert code == WS_CLOSE_TRY_AGAIN_LATER and "none may yield" in reason
            assert refusals(live) == {"yielded": 2.0, "full": 1.0, "open": float(TOTAL)}

    asyncio.run(scenario())
