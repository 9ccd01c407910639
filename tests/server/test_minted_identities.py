"""Minting identities buys nothing (docs/security.md, "Owners and shares"): a real uvicorn
with the OSC bridge, python-osc senders and raw UDP sockets each on a source port of its
own, a real WebSocket client (:mod:`tests.support.minted_identities`).

Before the admission, 512 rotating ports sending empty bundles evicted a sender that
renewed its contact every 0.5 s (its touch became pulses), and ``/phantomtouch/touch``
from 200 ports took a WebSocket client's one touch (``stolen``)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.server.test_owners_and_shares import free_udp_port
from tests.support.live_server import LiveServer
from tests.support.minted_identities import (
    osc_touches_against_a_websocket_touch,
    rotating_ports_against_a_renewer,
)

MAP = """\
watchdog_s = 3.0

[[receiver]]
address = "/avatar/parameters/PT_Arm_0"
x_cm = 0.0
y_cm = 0.0
"""
"""A map whose deadline (3 s) outlasts a renewal that comes late on a loaded machine: the
contact can only go by being evicted, never by its deadline."""


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, int]]:
    folder = tmp_path_factory.mktemp("minted")
    (folder / "map.toml").write_text(MAP, encoding="utf-8")
    osc_port = free_udp_port()
    args = ("--osc", f"127.0.0.1:{osc_port}", "--osc-map", str(folder / "map.toml"))
    with LiveServer(folder / "patterns.db", args=args) as server:
        yield server, osc_port


def test_rotating_source_ports_never_evict_a_sender_that_renews(
    live: tuple[LiveServer, int],
) -> None:
    server, osc_port = live
    seen = rotating_ports_against_a_renewer(server.url, osc_port)
    assert seen["sent"] > 4 * 512, seen  # every port was heard, again and again
    assert seen["fewest"] == 1.0 and seen["at_end"] == 1.0, seen  # the touch stayed on


def test_touches_from_200_source_ports_never_take_a_websocket_clients_touch(
    live: tuple[LiveServer, int],
) -> None:
    server, osc_port = live
    seen = osc_touches_against_a_websocket_touch(server.url, server.ws_url, osc_port)
    assert seen["voices"] >= 32, seen  # the OSC host filled the voices it could
    assert seen["state"] == "playing" and seen["reason"] is None, seen
