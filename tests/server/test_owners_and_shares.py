"""Owners and shares against a live server: every attack of :mod:`tests.support.owner_attacks`
(real uvicorn on loopback, real WebSockets, python-osc senders on ports of their own).

Owners are real sources with lifetimes (one per connection, per OSC sender, per HTTP client;
what an owner started ends when it goes), and a crowd of single holders cannot lock a
newcomer out of the voices or the contact slots (docs/owners.md).
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Iterator

import pytest
from websockets.asyncio.client import connect

from tests.support.live_server import LiveServer
from tests.support.owner_attacks import (
    QUIET_LONG,
    answer_to,
    http_crowd_voices,
    job_history_flood,
    osc_flooder_and_another_sender,
    osc_other_sender_renews,
    osc_sender_contacts,
    stop_all,
    ws_crowd_contacts,
    ws_crowd_voices,
    ws_touch_outlives_socket,
)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, int]]:
    folder = tmp_path_factory.mktemp("owners")
    osc_port = free_udp_port()
    # contacts held while a test fills every slot stay down without pings
    env = {"PHANTOMTOUCH_WATCHDOG_S": "30"}
    args = ("--osc", f"127.0.0.1:{osc_port}")
    with LiveServer(folder / "patterns.db", env=env, args=args) as server:
        yield server, osc_port


def test_another_osc_senders_messages_do_not_keep_a_silent_senders_contact_on(
    live: tuple[LiveServer, int],
) -> None:
    server, osc_port = live
    seen = osc_other_sender_renews(server.url, osc_port, seconds=3.0)
    # the map's watchdog is 1 s: A's contact went 1 s after A fell silent, whatever B sent
    assert seen == {"contacts": 0.0, "stayed_on": False}


def test_one_osc_sender_holds_its_quota_of_contacts_and_another_still_gets_one(
    live: tuple[LiveServer, int],
) -> None:
    server, osc_port = live
    seen = osc_sender_contacts(server.url, osc_port)
    # A's 11th is refused (its quota of max_contacts_per_connection=10); B's goes down
    # beside A's 10, none of A's taken; lifting B's leaves A's 10
    assert seen == {"after_down": 11.0, "after_lift": 10.0, "refused": 1.0}


def test_one_osc_sender_flooding_does_not_drop_another_senders_messages(
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    # a rate of 150/s for each sender: the flooder sends about 2,000 a second, B 90
    env = {"PHANTOMTOUCH_OSC_MESSAGES_PER_S": "150"}
    osc_port = free_udp_port()
    folder = tmp_path_factory.mktemp("osc-flood")
    args = ("--osc", f"127.0.0.1:{osc_port}")
    with LiveServer(folder / "patterns.db", env=env, args=args) as server:
        seen = osc_flooder_and_another_sender(server.url, osc_port, seconds=2.0)
    assert seen["flood"] > 500, seen  # the flooder was over its rate all along
    # B's own rate is far from its limit: its messages are handled, not A's excess
    assert seen["b_accepted"] >= 0.8 * seen["b_sent"], seen


def test_a_touch_played_over_a_websocket_stops_when_the_socket_closes(
    live: tuple[LiveServer, int],
) -> None:
    server, _ = live
    seen = ws_touch_outlives_socket(server.url, server.ws_url)
    assert seen == {"state": "stopped", "reason": "closed", "stayed_on": False}


def test_a_detached_touch_plays_on_within_its_own_quota(live: tuple[LiveServer, int]) -> None:
    server, _ = live
    seen = ws_touch_outlives_socket(server.url, server.ws_url, detached=True)
    assert seen["state"] == "playing" and seen["stayed_on"]  # asked for in so many words

    async def past_the_quota() -> list[dict]:
        touch = {**QUIET_LONG, "duration_s": 10.0}
        longest = {**QUIET_LONG, "duration_s": 601.0}
        async with connect(server.ws_url) as ws:
            answers = [await answer_to(ws, {"type": "play", "id": 9, **longest, "detached": True})]
            for k in range(5):
                answers.append(
                    await answer_to(ws, {"type": "play", "id": k, **touch, "detached": True})
                )
            answers.append(
                await answer_to(ws, {"type": "play", "id": 10, **touch, "detached": "yes"})
            )
        return answers

    answers = asyncio.run(past_the_quota())
    stop_all(server.url)
    assert answers[0]["code"] == "quota"
    assert "max_detached_seconds_per_client=600 s" in answers[0]["message"]
    assert [a["type"] for a in answers[1:5]] == ["ok"] * 4
    assert answers[5]["code"] == "quota"
    assert "max_detached_voices_per_client=4" in answers[5]["message"]
    assert answers[6]["type"] == "error" and answers[6]["fields"][0]["field"] == "detached"


def test_seventy_connections_holding_every_voice_leave_a_newcomer_one(
    live: tuple[LiveServer, int],
) -> None:
    server, _ = live
    seen = ws_crowd_voices(server.url, server.ws_url, crowd=70)
    assert seen["crowd"] == {"ok": 70}, seen  # each newcomer of the crowd got one too
    assert seen["newcomer"] == "ok", seen
    assert seen["state"] == "playing", seen
    assert seen["stolen"] >= 7, seen  # 70 + 1 touches, at most 64 voices: the oldest yield
    assert not seen["stayed_on"], seen  # every connection closed: its touch stopped


def test_sixty_four_addresses_holding_every_voice_leave_a_65th_one(
    live: tuple[LiveServer, int],
) -> None:
    server, _ = live
    seen = http_crowd_voices(server.url, crowd=64)
    assert seen["crowd"] == {"202": 64}, seen
    assert seen["newcomer"] == 202, seen
    assert seen["state"] == "playing", seen
    assert seen["stolen"] >= 1, seen


def test_128_connections_holding_every_contact_leave_a_newcomer_one(
    live: tuple[LiveServer, int],
) -> None:
    server, _ = live
    seen = ws_crowd_contacts(server.url, server.ws_url, crowd=128)
    assert seen["crowd_ok"] == 128, seen
    assert seen["newcomer"] == "ok", seen
    assert seen["released"] == ["quota"], seen  # the oldest holder yielded its one
    assert seen["contacts"] == 128.0, seen
    assert not seen["stayed_on"], seen


def test_another_clients_flood_does_not_evict_my_job_from_the_history(
    live: tuple[LiveServer, int],
) -> None:
    server, _ = live
    seen = job_history_flood(server.url, server.ws_url, flood=1100)
    assert seen["flooded"] == 1100, seen
    assert seen["mine"] == "finished", seen
    assert seen["flood_first"] == "unknown", seen  # the flood's own oldest made room
