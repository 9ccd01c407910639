"""Abuse of the service's inputs, bounded in count and time, on 127.0.0.1 (benchmarks).

Each function runs in a process of its own (:func:`tests.support.abuse.in_process`) and
returns what it sent and what the service answered.
"""

from __future__ import annotations

import base64
import os
import socket
import struct
import time
from typing import Any

from tests.support.live_server import HOST

_CONTACT = b"/phantomtouch/contact/x\x00\x00"
_VALID = _CONTACT + b",fff\x00\x00\x00\x00" + struct.pack(">fff", 1.9, 7.2, 0.5)
BAD_DATAGRAMS = (
    b"/phantomtouch/\xff\xfe\x00\x00,\x00\x00\x00",  # address not UTF-8
    _CONTACT + b",fxf\x00\x00\x00\x00" + b"\x00" * 12,  # unknown type tag
    _VALID[:-5],  # cut short
    b"#bundle\x00" + b"\x00" * 7 + b"\x01" + struct.pack(">i", 400) + _VALID,  # size > rest
    b"/phantomtouch/touch\x00,s\x00\x00\xc3(\x00\x00",  # string not UTF-8
    os.urandom(64),
)
"""One datagram of each kind the OSC bridge drops as a whole."""


def nested_bundle(depth: int) -> bytes:
    """A valid contact message inside ``depth`` bundles (20 bytes per level)."""
    prefixes = []
    size = len(_VALID)
    for _ in range(depth):
        prefixes.append(b"#bundle\x00" + b"\x00" * 7 + b"\x01" + struct.pack(">i", size))
        size += 20
    return b"".join(reversed(prefixes)) + _VALID


def osc_bad_datagrams(port: int, limit_s: float = 3.0, most: int = 300_000) -> dict[str, Any]:
    """Send :data:`BAD_DATAGRAMS` round and round as fast as possible."""
    sent = 0
    started = time.monotonic()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        while sent < most and time.monotonic() - started < limit_s:
            for datagram in BAD_DATAGRAMS:
                sock.sendto(datagram, (HOST, port))
            sent += len(BAD_DATAGRAMS)
    return {"sent": sent}


def osc_deep_bundles(
    port: int, depth: int = 500, limit_s: float = 3.0, most: int = 50_000
) -> dict[str, Any]:
    """Send bundles nested ``depth`` deep (10 KB each at 500) as fast as possible."""
    datagram = nested_bundle(depth)
    sent = 0
    started = time.monotonic()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        while sent < most and time.monotonic() - started < limit_s:
            sock.sendto(datagram, (HOST, port))
            sent += 1
    return {"sent": sent, "bytes": len(datagram)}


def invalid_utf8_frames(port: int, limit_s: float = 3.0, most: int = 2_000) -> dict[str, Any]:
    """Open a WebSocket, send one text frame that is not UTF-8, read the close; again."""
    sent = closed_1007 = 0
    started = time.monotonic()
    while sent < most and time.monotonic() - started < limit_s:
        with socket.create_connection((HOST, port), timeout=10.0) as sock:
            key = base64.b64encode(os.urandom(16)).decode()
            sock.sendall(
                (
                    f"GET /ws HTTP/1.1\r\nHost: {HOST}:{port}\r\nUpgrade: websocket\r\n"
                    f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                    "Sec-WebSocket-Version: 13\r\n\r\n"
                ).encode()
            )
            answer = b""
            while b"\r\n\r\n" not in answer:
                answer += sock.recv(4096)
            mask = os.urandom(4)
            payload = bytes(b ^ mask[i % 4] for i, b in enumerate(b"\xff\xfe{}"))
            sock.sendall(bytes([0x81, 0x80 | len(payload)]) + mask + payload)
            sent += 1
            data = answer.split(b"\r\n\r\n", 1)[1]
            while len(data) < 4:
                chunk = sock.recv(4096)
                if not chunk:
                    break
                data += chunk
            closed_1007 += data[:1] == b"\x88" and data[2:4] == struct.pack(">H", 1007)
    return {"sent": sent, "closed_1007": closed_1007}
