"""Attacks that mint identities (source ports) against a live server (docs/security.md,
"Owners and shares"); each ends what it started (``POST /stop``) and is bounded in count
and time.

- :func:`rotating_ports_against_a_renewer`: 512 UDP source ports of one host send empty
  OSC bundles while a sender of the same host renews its contact every 0.5 s;
- :func:`osc_touches_against_a_websocket_touch`: 200 OSC source ports each play a touch
  while a WebSocket client holds one.
"""

from __future__ import annotations

import asyncio
import socket
import struct
import threading
import time
from typing import Any

import httpx
from pythonosc.udp_client import SimpleUDPClient
from websockets.asyncio.client import connect

from tests.support.owner_attacks import QUIET_LONG, job_state, metric, stop_all, ws_play

EMPTY_BUNDLE = b"#bundle\x00" + struct.pack(">Q", 1)
"""An OSC bundle with no element, to be applied immediately (16 bytes)."""


def rotating_ports_against_a_renewer(
    url: str, osc_port: int, *, ports: int = 512, seconds: float = 3.0, rate_per_s: float = 800.0
) -> dict[str, Any]:
    """Sender A puts a contact down and renews it every 0.5 s (within the map's deadline)
    while ``ports`` sockets, each on a source port of its own, send empty bundles round
    robin for ``seconds`` at about ``rate_per_s`` (between two of A's renewals some 400
    other ports are heard: more than the bridge keeps, so the one heard longest ago is A,
    and a rate a loaded machine reads without the kernel dropping A's datagrams). Returns
    the datagrams sent, the
    fewest contacts down seen while they were sent (sampled every 20 ms) and the contacts
    down as the last was sent."""
    a = SimpleUDPClient("127.0.0.1", osc_port)
    a.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 0.5])
    deadline = time.monotonic() + 5.0
    while metric(url, "phantomtouch_active_contacts") < 1 and time.monotonic() < deadline:
        time.sleep(0.02)
    crowd = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(ports)]
    done = threading.Event()
    seen: list[float] = []

    def watch() -> None:
        while not done.is_set():
            seen.append(metric(url, "phantomtouch_active_contacts"))
            time.sleep(0.02)

    def renew() -> None:
        while not done.wait(0.5):
            a.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 0.5])

    threads = [threading.Thread(target=watch), threading.Thread(target=renew)]
    for thread in threads:
        thread.start()
    sent = 0
    start = time.monotonic()
    try:
        while (elapsed_s := time.monotonic() - start) < seconds:
            if sent < elapsed_s * rate_per_s:
                crowd[sent % ports].sendto(EMPTY_BUNDLE, ("127.0.0.1", osc_port))
                sent += 1
            else:
                time.sleep(0.002)
        at_end = metric(url, "phantomtouch_active_contacts")
    finally:
        done.set()
        for thread in threads:
            thread.join()
        for each in crowd:
            each.close()
    stop_all(url)
    return {"sent": sent, "fewest": min(seen), "at_end": at_end}


def osc_touches_against_a_websocket_touch(
    url: str, ws_url: str, osc_port: int, *, ports: int = 200
) -> dict[str, Any]:
    """A WebSocket client plays a quiet 2 h touch; then ``ports`` OSC senders, each on a
    source port of its own, play a stored quiet 2 h touch each (``/phantomtouch/touch``),
    more than the engine's voices. Returns the WebSocket touch's state afterwards and how
    many voices play."""
    stored = httpx.put(f"{url}/patterns/quiet-long", json=QUIET_LONG, timeout=10)
    assert stored.status_code in (200, 201), stored.text

    async def scenario() -> dict[str, Any]:
        async with connect(ws_url) as ws:
            answer = await ws_play(ws, QUIET_LONG)
            assert answer["type"] == "ok", answer
            job_id = answer["result"]["job_id"]
            senders = [SimpleUDPClient("127.0.0.1", osc_port) for _ in range(ports)]
            for _ in range(3):  # 3 x ports touches, a few ms apart
                for sender in senders:
                    sender.send_message("/phantomtouch/touch", "quiet-long")
                    await asyncio.sleep(0.002)
            await asyncio.sleep(0.5)
            voices = await asyncio.to_thread(metric, url, "phantomtouch_active_voices")
            job = await asyncio.to_thread(job_state, url, job_id)
        return {"state": job["state"], "reason": job.get("reason"), "voices": voices}

    try:
        return asyncio.run(scenario())
    finally:
        stop_all(url)
