"""The OSC bridge inside the service: generic addresses, bad OSC counted, /metrics."""

from __future__ import annotations

import math
import re
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pythonosc.udp_client import SimpleUDPClient

from phantomtouch.osc import service_link
from phantomtouch.server import create_app
from tests.support.service import LONG, make_settings


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_for(condition: Callable[[], Any], timeout_s: float = 3.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        result = condition()
        if result or time.monotonic() > deadline:
            return result
        time.sleep(0.01)


@pytest.fixture
def service(tmp_path: Path) -> Iterator[tuple[TestClient, SimpleUDPClient, int]]:
    port = free_udp_port()
    settings = make_settings(tmp_path, osc_listen=f"127.0.0.1:{port}", osc_messages_per_s=200.0)
    with TestClient(create_app(settings, attach=[service_link.attach])) as client:
        yield client, SimpleUDPClient("127.0.0.1", port), port


def status(client: TestClient) -> dict[str, Any]:
    return client.app.state.service.engine.status().to_dict()  # type: ignore[attr-defined]


def osc_counts(client: TestClient) -> dict[str, float]:
    text = client.get("/metrics").text
    return {
        m[1]: float(m[2])
        for m in re.finditer(r'phantomtouch_osc_messages_total\{outcome="(\w+)"\} (\S+)', text)
    }


def test_contact_down_move_and_lift(service) -> None:
    client, osc, _ = service
    osc.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 0.5])
    contacts = wait_for(lambda: status(client)["active_contacts"])
    # OSC floats are float32: 1.9 arrives as 1.899999976...
    assert [(c["contact"], c["x_cm"], c["y_cm"]) for c in contacts] == [
        ("contact-finger", pytest.approx(1.9, rel=1e-7), pytest.approx(7.2, rel=1e-7))
    ]
    osc.send_message("/phantomtouch/contact/finger", [0.0, 3.0, 0.8])
    assert wait_for(lambda: status(client)["active_contacts"][0]["y_cm"] == 3.0)
    osc.send_message("/phantomtouch/contact/finger", [0.0, 3.0, 0.0])
    assert wait_for(lambda: not status(client)["active_contacts"])
    assert wait_for(lambda: osc_counts(client).get("accepted") == 3)


def test_touch_plays_stored_patterns_and_presets_and_stop_stops(service) -> None:
    client, osc, _ = service
    assert client.put("/patterns/long-rest", json=LONG).status_code == 200
    osc.send_message("/phantomtouch/touch", "long-rest")
    assert wait_for(lambda: status(client)["active_voices"] == 1)
    osc.send_message("/phantomtouch/touch", "exp2/curved")
    assert wait_for(lambda: status(client)["active_voices"] == 2)
    osc.send_message("/phantomtouch/contact/a", [1.0, 5.0, 0.4])
    assert wait_for(lambda: status(client)["active_contacts"])
    osc.send_message("/phantomtouch/stop", [])
    assert wait_for(
        lambda: status(client)["active_voices"] == 0 and not status(client)["active_contacts"]
    )
    # Unknown names are refused and counted; the bridge goes on.
    osc.send_message("/phantomtouch/touch", "no-such-pattern")
    osc.send_message("/phantomtouch/touch", "exp9/none")
    assert wait_for(lambda: osc_counts(client).get("refused") == 2)
    assert osc_counts(client)["accepted"] == 4  # two touches, a contact, a stop


def test_bad_osc_is_dropped_and_counted_and_never_vibrates(service) -> None:
    client, osc, port = service
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        raw.sendto(b"\x00\x01not osc at all", ("127.0.0.1", port))
        raw.sendto(b"/phantomtouch/contact/x\x00,fff\x00\x00\x00\x00", ("127.0.0.1", port))
    osc.send_message("/phantomtouch/contact/a", ["one", 2.0, 0.5])  # wrong type
    osc.send_message("/phantomtouch/contact/a", [1.0, 2.0])  # too few
    osc.send_message("/phantomtouch/contact/a", [math.nan, 2.0, 0.5])
    osc.send_message("/phantomtouch/contact/a", [1.0, math.inf, 0.5])
    osc.send_message("/phantomtouch/contact/a", [1.0, 2.0, 1.5])  # intensity > 1
    osc.send_message("/phantomtouch/contact/a b", [1.0, 2.0, 0.5])  # bad id
    osc.send_message("/avatar/parameters/PT_Arm_0", "near")
    osc.send_message("/avatar/parameters/PT_Arm_0", 2.0)
    osc.send_message("/avatar/parameters/Unknown", 0.5)
    osc.send_message("/phantomtouch/stop", 1)
    expected = {
        "malformed": 2,
        "bad_arguments": 5,
        "not_finite": 2,
        "out_of_range": 2,
        "unknown_address": 1,
    }
    assert wait_for(lambda: all(osc_counts(client).get(k) == v for k, v in expected.items()))
    counts = osc_counts(client)
    assert counts["accepted"] == 0
    assert status(client)["active_contacts"] == []

    # A flood: 1000 messages in 20 ms against 200/s with one second of burst.
    started_s = time.monotonic()
    for burst in range(20):
        for _ in range(50):
            osc.send_message("/avatar/parameters/PT_Arm_7", 0.0)
        time.sleep(0.001 * (burst % 2))

    def settled() -> dict[str, float] | None:
        before = osc_counts(client)
        time.sleep(0.1)
        after = osc_counts(client)
        return after if after == before else None

    counts = wait_for(settled)
    # The bucket refills while the bridge works through the burst, which may take longer
    # than the sending did: the time until the counts settled bounds it.
    elapsed_s = time.monotonic() - started_s
    arrived = counts["accepted"] + counts["flood"]
    assert arrived > 900  # UDP: the kernel may drop a few before the bridge sees them
    assert counts["accepted"] <= 200 + 200 * elapsed_s + 1
    assert counts["flood"] >= arrived - 200 - 200 * elapsed_s - 1
    assert counts["flood"] >= 500
    # The service is still up and nothing vibrates.
    assert client.get("/health").status_code == 200
    assert status(client)["active_contacts"] == []
