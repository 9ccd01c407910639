"""No datagram kills the OSC input: a real ``phantomtouch serve --osc`` process, python-osc
and raw UDP sockets.

Each bad datagram is dropped, counted by reason in ``/metrics``, logged in one line (no
traceback), and the bridge goes on: a valid lift and ``/phantomtouch/stop`` afterwards
still work, and a contact whose sender went silent is released by the watchdog.
"""

from __future__ import annotations

import random
import re
import socket
import struct
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from pythonosc.udp_client import SimpleUDPClient

from phantomtouch.osc.counters import REASONS
from phantomtouch.osc.packets import MAX_BUNDLE_DEPTH
from tests.osc.test_service_osc import free_udp_port
from tests.support.live_server import LiveServer

CONTACT = "/phantomtouch/contact/x"


def osc_string(text: bytes) -> bytes:
    """An OSC string: the bytes, a null, nulls to a multiple of 4."""
    return text + b"\x00" * (4 - len(text) % 4)


IMMEDIATELY = b"\x00" * 7 + b"\x01"


def bundle(*elements: bytes) -> bytes:
    body = b"".join(struct.pack(">i", len(e)) + e for e in elements)
    return b"#bundle\x00" + IMMEDIATELY + body


def nested(depth: int, inner: bytes) -> bytes:
    """``inner`` in ``depth`` bundles, each the only element of the next."""
    prefixes = []
    size = len(inner)
    for _ in range(depth):
        prefixes.append(b"#bundle\x00" + IMMEDIATELY + struct.pack(">i", size))
        size += 20
    return b"".join(reversed(prefixes)) + inner


VALID = osc_string(CONTACT.encode()) + osc_string(b",fff") + struct.pack(">fff", 1.9, 7.2, 0.5)

BAD: dict[str, bytes] = {
    "not_utf8": b"/phantomtouch/\xff\xfe\x00\x00,\x00\x00\x00",
    "too_deep": nested(500, VALID),
    "bad_type_tag": osc_string(CONTACT.encode()) + osc_string(b",fxf") + b"\x00" * 12,
    "malformed": VALID[:-5],
    "bad_bundle_size": bundle(VALID)[:-8],
}
"""One datagram per reason: a non-UTF-8 address (the issue's command), bundles nested 500
deep, an unknown type tag, a message cut short, and a bundle whose element declares more
bytes than follow."""
NOT_UTF8_STRING = osc_string(b"/phantomtouch/touch") + osc_string(b",s") + osc_string(b"\xc3(")


@pytest.fixture
def osc_server(tmp_path: Path) -> Iterator[tuple[LiveServer, int]]:
    port = free_udp_port()
    server = LiveServer(tmp_path / "patterns.db", args=("--osc", f"127.0.0.1:{port}"))
    with server:
        yield server, port


def wait_for(condition: Callable[[], Any], timeout_s: float = 5.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        result = condition()
        if result or time.monotonic() > deadline:
            return result
        time.sleep(0.02)


def metrics(server: LiveServer) -> dict[str, float]:
    text = httpx.get(f"{server.url}/metrics").text
    counts = {
        m[1]: float(m[2])
        for m in re.finditer(r'phantomtouch_osc_messages_total\{outcome="(\w+)"\} (\S+)', text)
    }
    active = re.search(r"^phantomtouch_active_contacts (\S+)", text, re.M)
    counts["active_contacts"] = float(active[1]) if active else -1.0
    return counts


def send_raw(port: int, *datagrams: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        for datagram in datagrams:
            raw.sendto(datagram, ("127.0.0.1", port))


def test_each_bad_datagram_is_dropped_counted_logged_once_and_the_bridge_goes_on(
    osc_server: tuple[LiveServer, int],
) -> None:
    server, port = osc_server
    client = SimpleUDPClient("127.0.0.1", port)
    client.send_message(CONTACT, [1.9, 7.2, 0.5])
    assert wait_for(lambda: metrics(server)["active_contacts"] == 1)
    for datagram in BAD.values():
        send_raw(port, datagram, datagram)  # twice: the second is counted, not logged
    send_raw(port, NOT_UTF8_STRING)
    expected = {reason: 2 for reason in BAD} | {"not_utf8": 3}
    assert wait_for(lambda: all(metrics(server).get(k) == v for k, v in expected.items())), metrics(
        server
    )
    # The input still runs: the contact moves, then a valid lift releases it at once.
    client.send_message(CONTACT, [1.9, 3.0, 0.5])
    client.send_message(CONTACT, [1.9, 3.0, 0.0])
    assert wait_for(lambda: metrics(server)["active_contacts"] == 0)
    client.send_message(CONTACT, [1.9, 7.2, 0.5])
    assert wait_for(lambda: metrics(server)["active_contacts"] == 1)
    client.send_message("/phantomtouch/stop", [])
    assert wait_for(lambda: metrics(server)["active_contacts"] == 0)
    assert metrics(server)["accepted"] == 5
    health = httpx.get(f"{server.url}/health").json()
    assert health["status"] == "ok"
    assert health["inputs"]["osc"] == {"state": "running", "restarts": 0}
    log = server.log()
    assert "Traceback" not in log
    for reason in BAD:
        assert len(re.findall(rf"osc: dropped \({reason}\)", log)) == 1, log


def fuzz_datagrams(rng: random.Random, count: int) -> Iterator[bytes]:
    """Random, truncated, deeply bundled, non-UTF-8 and wrongly typed datagrams, none valid."""
    for k in range(count):
        kind = k % 7
        if kind == 0:
            yield rng.randbytes(rng.randrange(0, 200))
        elif kind == 1:  # python-osc pads a last float cut short (Reaktor sends those)
            yield VALID[: rng.randrange(len(VALID) - 4)]
        elif kind == 2:
            yield nested(rng.randrange(MAX_BUNDLE_DEPTH + 1, 2000), VALID)
        elif kind == 3:
            junk = bytes(rng.randrange(0x80, 0x100) for _ in range(rng.randrange(1, 20)))
            yield osc_string(b"/phantomtouch/" + junk) + osc_string(b",fff") + b"\x00" * 12
        elif kind == 4:
            tags = "".join(rng.choice("xyzAQ!ifs") for _ in range(rng.randrange(1, 8)))
            tags += rng.choice("xyzAQ")
            yield osc_string(CONTACT.encode()) + osc_string(f",{tags}".encode()) + b"\x00" * 8
        elif kind == 5:  # cut inside the second element: its size exceeds what follows
            whole = bundle(VALID, VALID)
            yield whole[: rng.randrange(len(whole) - len(VALID) + 1, len(whole))]
        else:
            yield b"#bundle\x00" + rng.randbytes(rng.randrange(0, 64))


def test_fuzzed_datagrams_leave_the_bridge_running_and_the_watchdog_releases(
    osc_server: tuple[LiveServer, int],
) -> None:
    server, port = osc_server
    client = SimpleUDPClient("127.0.0.1", port)
    client.send_message(CONTACT, [1.9, 7.2, 0.5])
    assert wait_for(lambda: metrics(server)["active_contacts"] == 1)
    rng = random.Random(22)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        for datagram in fuzz_datagrams(rng, 1400):
            raw.sendto(datagram, ("127.0.0.1", port))
    # No datagram was valid, so the contact's sender is silent: the map's 1 s watchdog
    # releases it.
    assert wait_for(lambda: metrics(server)["active_contacts"] == 0, timeout_s=10.0)
    counts = metrics(server)
    assert counts["accepted"] == 1
    # The bridge runs on: a new contact goes down.
    client.send_message("/phantomtouch/contact/y", [1.9, 7.2, 0.5])
    assert wait_for(lambda: metrics(server)["active_contacts"] == 1)
    assert httpx.get(f"{server.url}/health").json()["status"] == "ok"
    log = server.log()
    assert "Traceback" not in log
    # One line per reason and 10 s at most, whatever the flood.
    assert len([line for line in log.splitlines() if "osc: dropped" in line]) <= 2 * len(REASONS)
