"""A bHaptics SDK1 client written from the protocol study alone: raw JSON over ``websockets``.

It imports nothing of phantomtouch. It sends what the real clients send -- the C++
``haptic_library`` (PascalCase, integer ``Position``, both arrays always present),
bHapticsLib (lowercase ``key``/``project``, arrays only when filled, ``app_id``/``app_name``
query) and old tact-python (``Project`` with ``Tracks``/``Layout``, camelCase ``Frame``) --
and checks every status the Player sends back as the C++ SDK reads it: all five keys,
``Status`` with integer arrays for every position, ``ConnectedPositions`` strings.

:class:`RawSocket` is a WebSocket client made by hand (handshake, masked frames), for what
a library client hides: whether the server ever sends an RFC 6455 ping, and a frame
header announcing a message larger than any server should read.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import socket
import struct
import time
from typing import Any

import websockets

STATUS_KEYS = {
    "RegisteredKeys",
    "ActiveKeys",
    "ConnectedDeviceCount",
    "ConnectedPositions",
    "Status",
}
STATUS_MOTORS = {"ForearmL": 6, "ForearmR": 6, "VestFront": 20, "VestBack": 20, "Head": 6}
"""The Player's status positions and their motor counts (arms: Tactosy2, 6 motors)."""


def check_status(status: Any) -> dict[str, Any]:
    """The status as the C++ SDK reads it (``j.at`` on every key); raises AssertionError."""
    assert isinstance(status, dict), status
    assert set(status) >= STATUS_KEYS, f"status lacks {STATUS_KEYS - set(status)}"
    assert all(isinstance(k, str) for k in status["RegisteredKeys"])
    assert all(isinstance(k, str) for k in status["ActiveKeys"])
    assert isinstance(status["ConnectedDeviceCount"], int)
    assert all(isinstance(p, str) for p in status["ConnectedPositions"])
    for position, motors in STATUS_MOTORS.items():
        levels = status["Status"][position]
        assert len(levels) == motors, (position, levels)
        assert all(isinstance(v, int) and 0 <= v <= 100 for v in levels), (position, levels)
    return status


def crowd_project(voices: int, length_ms: int, step_ms: int) -> dict[str, Any]:
    """A Designer project of ``voices`` path feedbacks (one voice each, study §3.1) on the
    left arm, each moving along the band for ``length_ms`` with a keyframe every ``step_ms``:
    a key the stand-in takes a while to plan."""
    times = range(0, length_ms + 1, step_ms)
    feedback = [
        {
            "movingPattern": "CONST_SPEED",
            "playbackType": "NONE",
            "visible": True,
            "pointList": [
                {"time": t, "x": (k % 10) / 10, "y": t / length_ms, "intensity": 0.3} for t in times
            ],
        }
        for k in range(voices)
    ]
    mode = {
        "mode": "PATH_MODE",
        "dotMode": {"dotConnected": False, "feedback": []},
        "pathMode": {"feedback": feedback},
    }
    effect = {"startTime": 0, "offsetTime": length_ms, "modes": {"ForearmL": mode}}
    return {
        "layout": {"type": "Tactosy2", "layouts": {}},
        "tracks": [{"enable": True, "effects": [effect]}],
    }


def frame_submits(count: int) -> str:
    """One message asking for ``count`` frame submits, each under a key of its own."""
    submit = [
        {
            "Type": "frame",
            "Key": f"spam-{k}",
            "Frame": {
                "Position": "ForearmL",
                "DotPoints": [{"Index": (k + i) % 20, "Intensity": 40} for i in range(8)],
                "PathPoints": [],
                "DurationMillis": 100,
            },
        }
        for k in range(count)
    ]
    return json.dumps({"Register": [], "Submit": submit})


class PlayerClient:
    """One connection; every status received is kept with its arrival time
    (``time.monotonic()``, the clock the server's ``/clock`` reports)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.statuses: list[tuple[float, dict[str, Any]]] = []
        self._arrived = asyncio.Condition()
        self._reader: asyncio.Task[None] | None = None
        self.ws: Any = None

    async def __aenter__(self) -> PlayerClient:
        self.ws = await websockets.connect(
            self.url, ping_interval=None, compression=None, max_size=None
        )
        self._reader = asyncio.create_task(self._read())
        await self.wait_statuses(1)
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self._reader is not None
        await self.ws.close()
        self._reader.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._reader

    async def _read(self) -> None:
        with contextlib.suppress(websockets.ConnectionClosed):
            async for text in self.ws:
                status = check_status(json.loads(text))
                async with self._arrived:
                    self.statuses.append((time.monotonic(), status))
                    self._arrived.notify_all()

    async def wait_statuses(self, count: int, timeout_s: float = 10.0) -> dict[str, Any]:
        """Wait until ``count`` statuses arrived in all; the newest."""
        async with self._arrived:
            await asyncio.wait_for(
                self._arrived.wait_for(lambda: len(self.statuses) >= count), timeout_s
            )
            return self.statuses[-1][1]

    async def send(self, message: Any, timeout_s: float = 10.0) -> tuple[float, dict[str, Any]]:
        """Send one message (an object as JSON, a string as it is) and wait for the status
        that answers it (at most ``timeout_s``); (the send time, that status)."""
        before = len(self.statuses)
        sent_s = time.monotonic()
        await self.ws.send(message if isinstance(message, str) else json.dumps(message))
        status = await self.wait_statuses(before + 1, timeout_s)
        return sent_s, status

    def active_between(self, start_s: float, end_s: float) -> set[str]:
        """Every name any status received in [start_s, end_s] listed as active."""
        return {
            name
            for at_s, status in self.statuses
            if start_s <= at_s <= end_s
            for name in status["ActiveKeys"]
        }


class RawSocket:
    """A WebSocket client by hand: the opening handshake, masked text frames, and the
    opcodes of what arrives."""

    def __init__(self, host: str, port: int, path: str, headers: dict[str, str] | None = None):
        self.sock = socket.create_connection((host, port), timeout=10.0)
        key = base64.b64encode(os.urandom(16)).decode()
        lines = [
            f"GET {path} HTTP/1.1",
            f"Host: {host}:{port}",
            "Upgrade: websocket",
            "Connection: Upgrade",
            f"Sec-WebSocket-Key: {key}",
            "Sec-WebSocket-Version: 13",
            *(f"{name}: {value}" for name, value in (headers or {}).items()),
        ]
        self.sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        self.buffer = b""
        while b"\r\n\r\n" not in self.buffer:
            chunk = self.sock.recv(4096)
            if not chunk:
                break
            self.buffer += chunk
        head, _, self.buffer = self.buffer.partition(b"\r\n\r\n")
        self.status_line = head.split(b"\r\n", 1)[0].decode()
        self.response_head = head.decode(errors="replace")

    @property
    def http_status(self) -> int:
        return int(self.status_line.split()[1])

    def send_header(self, opcode: int, length: int) -> None:
        """A final frame's header announcing ``length`` payload bytes (masked, as a client)."""
        if length < 126:
            header = struct.pack("!BB", 0x80 | opcode, 0x80 | length)
        elif length < 1 << 16:
            header = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, length)
        else:
            header = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, length)
        self.sock.sendall(header + b"\0\0\0\0")  # a zero mask: the payload goes as it is

    def send_text(self, text: str) -> None:
        data = text.encode()
        self.send_header(0x1, len(data))
        self.sock.sendall(data)

    def read_frame(self, timeout_s: float) -> tuple[int, bytes] | None:
        """The next frame's (opcode, payload); None when nothing arrives in ``timeout_s``
        or the connection ended."""
        self.sock.settimeout(timeout_s)
        try:
            while True:
                frame = self._parse()
                if frame is not None:
                    return frame
                chunk = self.sock.recv(65536)
                if not chunk:
                    return None
                self.buffer += chunk
        except (TimeoutError, ConnectionResetError):
            return None

    def _parse(self) -> tuple[int, bytes] | None:
        if len(self.buffer) < 2:
            return None
        opcode, length = self.buffer[0] & 0x0F, self.buffer[1] & 0x7F
        offset = 2
        if length == 126:
            if len(self.buffer) < 4:
                return None
            (length,) = struct.unpack("!H", self.buffer[2:4])
            offset = 4
        elif length == 127:
            if len(self.buffer) < 10:
                return None
            (length,) = struct.unpack("!Q", self.buffer[2:10])
            offset = 10
        if len(self.buffer) < offset + length:
            return None
        payload = self.buffer[offset : offset + length]
        self.buffer = self.buffer[offset + length :]
        return opcode, payload

    def close(self) -> None:
        self.sock.close()
