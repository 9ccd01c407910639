"""Failures: a dead armband, malformed fleet messages, a NATS server that dies."""

from __future__ import annotations

import asyncio
import json
import time

import httpx
import nats

from phantomtouch.fleet.nats_config import inbox_prefix
from tests.fleet.conftest import CLIENT, Fleet
from tests.support.fleet import TTL_S, ArmbandNode
from tests.support.service import STROKE
from tests.support.waiting import wait_until
from tests.support.yardstick import WakeUpLag


def test_a_dead_armband_is_refused_by_name_never_accepted(fleet: Fleet) -> None:
    node = ArmbandNode(fleet.folder, fleet.cluster, "a4", "lab-c")
    node.start()
    gateway = fleet.gateways[0]

    def listed() -> set[str]:
        return {r["armband"] for r in httpx.get(f"{gateway.url}/armbands").json()}

    try:
        wait_until(lambda: "a4" in listed(), 30.0, "a4 registered")
        assert httpx.post(f"{gateway.url}/armbands/a4/touch", json=STROKE).status_code == 202
        statuses = set()
        with WakeUpLag() as lag:  # 3 s past the TTL on a quiet machine, more as it is late
            node.kill()
            killed_s = time.monotonic()
            while "a4" in listed():
                answer = httpx.post(f"{gateway.url}/armbands/a4/touch", json=STROKE, timeout=10.0)
                statuses.add(answer.status_code)
                assert answer.status_code in (404, 503), answer.text
                assert "armband='a4'" in answer.json()["error"]["message"]
                assert time.monotonic() - killed_s < 60.0, "a4 still registered"
            gone_s = time.monotonic() - killed_s
        assert gone_s < TTL_S + 3.0 + 10 * lag.worst_s, ("a4 registered past its TTL", gone_s)
        assert 503 in statuses  # while registered, nobody answers its subjects
        answer = httpx.post(f"{gateway.url}/armbands/a4/touch", json=STROKE)
        assert answer.status_code == 404
        assert "armband='a4' is not online" in answer.json()["error"]["message"]
    finally:
        node.kill()


async def _send_bad_messages(url: str, user: str, password: str) -> dict[str, object]:
    nc = await nats.connect(url, user=user, password=password, inbox_prefix=inbox_prefix(user))
    try:
        subject = "phantomtouch.armband.a1.contact"
        await nc.publish(subject, b"not json")
        await nc.publish(
            subject,
            json.dumps(
                {"type": "move", "owner": "x", "contact": "c", "x_cm": 1, "y_cm": 1}
            ).encode(),
        )
        await nc.publish(
            subject, b'{"type": "down", "owner": "x", "pad": "' + b"x" * 70_000 + b'"}'
        )
        await nc.publish(
            subject,
            json.dumps(
                {"type": "down", "owner": "x", "contact": "c", "x_cm": "far", "y_cm": 1}
            ).encode(),
        )
        await nc.flush()
        reply = await nc.request("phantomtouch.armband.a1.touch", b"[1, 2", timeout=5.0)
        return dict(json.loads(reply.data))
    finally:
        await nc.close()


def test_malformed_fleet_messages_are_counted_and_dropped(fleet: Fleet) -> None:
    node = fleet.nodes["a1"]

    def count(subject: str, outcome: str) -> float:
        return node.metric(
            "phantomtouch_fleet_messages_total", f'outcome="{outcome}",subject="{subject}"'
        )

    before = {k: count("contact", k) for k in ("invalid", "refused", "too_large")}
    access = fleet.cluster.credentials(CLIENT)
    answer = asyncio.run(
        _send_bad_messages(
            fleet.cluster.urls[1],
            access["PHANTOMTOUCH_FLEET_USER"],
            access["PHANTOMTOUCH_FLEET_PASSWORD"],
        )
    )
    assert answer["status"] == 422
    assert answer["body"]["error"]["code"] == "invalid"  # type: ignore[index]
    wait_until(lambda: count("contact", "too_large") > before["too_large"], 30.0, "counted")
    assert count("contact", "invalid") > before["invalid"]  # x_cm="far"
    assert count("contact", "refused") >= before["refused"] + 2  # not JSON; move before down
    assert count("touch", "invalid") >= 1
    assert httpx.get(f"{node.url}/health").json()["status"] == "ok"
    assert httpx.post(f"{fleet.gateways[1].url}/armbands/a1/touch", json=STROKE).status_code == 202


def test_touches_go_on_after_a_nats_server_dies(fleet: Fleet) -> None:
    fleet.cluster.kill(0)
    try:
        killed_s = time.monotonic()
        for gateway in fleet.gateways:
            for armband in fleet.nodes:
                url = f"{gateway.url}/armbands/{armband}/touch"
                wait_until(
                    lambda u=url: httpx.post(u, json=STROKE, timeout=10.0).status_code == 202,
                    10.0,
                    f"{armband} through {gateway.url} after the NATS server died",
                )
        recovered_s = time.monotonic() - killed_s
        print(f"every armband through both gateways again after {recovered_s:.2f} s")
        for _ in range(5):
            for gateway in fleet.gateways:
                for armband in fleet.nodes:
                    answer = httpx.post(f"{gateway.url}/armbands/{armband}/touch", json=STROKE)
                    assert answer.status_code == 202, answer.text

        def listed() -> set[str]:
            answer = httpx.get(f"{fleet.gateways[1].url}/armbands", timeout=10.0)
            return {r["armband"] for r in answer.json()} if answer.status_code == 200 else set()

        # The registry's stream elects a new leader among the two servers left (JetStream
        # notices a lost peer within seconds); heartbeats then put every armband back.
        wait_until(lambda: listed() == set(fleet.nodes), 15.0, "every armband registered again")
        print(f"registry complete again after {time.monotonic() - killed_s:.2f} s")
    finally:
        fleet.cluster.restart(0)
