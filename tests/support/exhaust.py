"""Crowds that try to take every file descriptor of a live server, loopback only.

Each runs in a process of its own (``tests.support.abuse.in_process``), bounded in count
and time, and raises its own open-file limit to the hard one so that it can hold
more connections than the server.
"""

from __future__ import annotations

import asyncio
import base64
import os
import struct
import sys
import time
from pathlib import Path
from typing import Any

from tests.support.live_server import HOST, LiveServer

UPGRADE = (
    "GET /ws{query} HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
)


class LimitedServer(LiveServer):
    """A server whose open-file limit is ``open_files`` (soft and hard): a small machine."""

    open_files = 256

    def command(self) -> list[str]:
        shim = (
            "import os, resource, sys; "
            f"resource.setrlimit(resource.RLIMIT_NOFILE, ({self.open_files}, {self.open_files})); "
            "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"
        )
        return [sys.executable, "-c", shim, *super().command()[1:]]


def _raise_own_limit() -> None:
    if sys.platform == "win32":
        return
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))


def crowd(
    port: int,
    idle_ws: int,
    slow: int,
    hold_s: float,
    ready_file: str | None = None,
    token: str | None = None,
) -> dict[str, Any]:
    """``idle_ws`` WebSocket handshakes (with ``token`` if given) that then stay silent,
    and ``slow`` connections sending one header line a second, each reopened at once
    when the server closes it, for ``hold_s`` s. ``ready_file`` is created once every
    connection was tried once.

    Returns how many WebSockets were upgraded (101), how many connections the server
    answered otherwise or closed, and how many were opened in all.
    """
    _raise_own_limit()

    async def run() -> dict[str, Any]:
        query = f"?token={token}" if token else ""
        counts = {"upgraded": 0, "answered_or_closed": 0, "opened": 0, "connect_failed": 0}
        end = time.monotonic() + hold_s

        async def idle_socket(index: int) -> None:
            while time.monotonic() < end:
                try:
                    reader, writer = await asyncio.open_connection(HOST, port)
                except OSError:
                    counts["connect_failed"] += 1
                    await asyncio.sleep(0.05)
                    continue
                counts["opened"] += 1
                key = base64.b64encode(os.urandom(16)).decode()
                try:
                    writer.write(UPGRADE.format(key=key, query=query).encode())
                    status = await asyncio.wait_for(reader.readline(), end - time.monotonic())
                    if b" 101 " in status:
                        counts["upgraded"] += 1
                        await asyncio.wait_for(reader.read(), max(0.0, end - time.monotonic()))
                    counts["answered_or_closed"] += 1
                except (TimeoutError, OSError):
                    pass
                finally:
                    writer.close()

        async def slow_socket(index: int) -> None:
            while time.monotonic() < end:
                try:
                    reader, writer = await asyncio.open_connection(HOST, port)
                except OSError:
                    counts["connect_failed"] += 1
                    await asyncio.sleep(0.05)
                    continue
                counts["opened"] += 1
                try:
                    writer.write(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
                    while time.monotonic() < end and not reader.at_eof():
                        writer.write(f"X-Slow-{index}: 1\r\n".encode())
                        await writer.drain()
                        try:
                            await asyncio.wait_for(reader.read(4096), 1.0)
                        except TimeoutError:
                            continue
                    counts["answered_or_closed"] += 1
                except OSError:
                    pass
                finally:
                    writer.close()

        tasks = []
        for index in range(max(idle_ws, slow)):
            if index < idle_ws:
                tasks.append(asyncio.create_task(idle_socket(index)))
            if index < slow:
                tasks.append(asyncio.create_task(slow_socket(index)))
            if index % 50 == 49:
                await asyncio.sleep(0.01)
        await asyncio.sleep(1.0)
        if ready_file is not None:
            Path(ready_file).touch()
        await asyncio.gather(*tasks, return_exceptions=True)
        return counts

    return asyncio.run(run())


def endless_header(port: int, megabytes: int = 20) -> dict[str, Any]:
    """One request whose one header value never ends: ``megabytes`` MB sent until the
    server answers or closes. Returns the bytes sent and the status line (if any)."""

    async def run() -> dict[str, Any]:
        reader, writer = await asyncio.open_connection(HOST, port)
        writer.write(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Endless: ")
        sent = 0
        chunk = b"a" * 65536
        try:
            while sent < megabytes << 20 and not reader.at_eof():
                writer.write(chunk)
                await writer.drain()
                sent += len(chunk)
        except OSError:
            pass
        try:
            status = await asyncio.wait_for(reader.readline(), 5.0)
        except (TimeoutError, OSError):
            status = b""
        writer.close()
        return {"sent": sent, "status": status.decode(errors="replace").strip()}

    return asyncio.run(run())


def _frame(opcode: int, payload: bytes) -> bytes:
    """A masked client frame (FIN set) with a payload under 126 bytes."""
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return struct.pack("!BB", 0x80 | opcode, 0x80 | len(payload)) + mask + masked


def ping_frames(
    port: int, limit_s: float = 4.0, most: int = 4_000_000, token: str | None = None
) -> dict[str, Any]:
    """WebSocket ping *control frames* (not JSON messages; ``token`` in the query if
    given) in a tight loop until the
    server closes the connection or the bounds are reached. Returns the pings sent, the
    close code the server sent (None if none) and when (s after the first ping)."""

    async def run() -> dict[str, Any]:
        reader, writer = await asyncio.open_connection(HOST, port)
        key = base64.b64encode(os.urandom(16)).decode()
        query = f"?token={token}" if token else ""
        writer.write(UPGRADE.format(key=key, query=query).encode())
        head = await reader.readuntil(b"\r\n\r\n")
        assert b" 101 " in head.split(b"\r\n")[0], head
        batch = _frame(0x9, b"p") * 1000
        sent = 0
        code: int | None = None
        closed_s = float("nan")
        started = time.monotonic()
        received = bytearray()

        async def read() -> None:
            nonlocal code, closed_s
            while True:
                data = await reader.read(1 << 16)
                if not data:
                    break
                received.extend(data)
                found = _close_code(received)
                if found is not None:
                    code = found
                    closed_s = time.monotonic() - started
                    break
            if closed_s != closed_s:
                closed_s = time.monotonic() - started

        reading = asyncio.create_task(read())
        try:
            while sent < most and time.monotonic() - started < limit_s and not reading.done():
                writer.write(batch)
                sent += 1000
                await writer.drain()
        except OSError:
            pass
        try:
            await asyncio.wait_for(reading, 5.0)
        except TimeoutError:
            reading.cancel()
        writer.close()
        return {"sent": sent, "code": code, "closed_after_s": closed_s}

    return asyncio.run(run())


def _close_code(data: bytearray) -> int | None:
    """The code of the first close frame among the server's (unmasked) frames."""
    at = 0
    while at + 2 <= len(data):
        opcode = data[at] & 0x0F
        length = data[at + 1] & 0x7F
        header = 2
        if length == 126:
            if at + 4 > len(data):
                return None
            length = struct.unpack("!H", data[at + 2 : at + 4])[0]
            header = 4
        elif length == 127:
            if at + 10 > len(data):
                return None
            length = struct.unpack("!Q", data[at + 2 : at + 10])[0]
            header = 10
        if at + header + length > len(data):
            return None
        if opcode == 0x8:
            payload = data[at + header : at + header + length]
            return struct.unpack("!H", payload[:2])[0] if len(payload) >= 2 else 1005
        at += header + length
    del data[:at]
    return None
