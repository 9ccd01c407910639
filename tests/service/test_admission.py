"""The admission (phantomtouch/service/admission): one policy table, a handle per source,
shares by principal, slots that make room, stop voiding; over a real engine rendering into
a capture sink."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from phantomtouch.clips.tact_score import Score, Voice
from phantomtouch.engine import Engine
from phantomtouch.errors import ParameterError, ProtocolError
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile, TouchPattern
from phantomtouch.service.admission import (
    KINDS,
    Admission,
    Handle,
    policy_table,
    principal_for,
)
from phantomtouch.service.errors import QuotaError, TooLargeError
from phantomtouch.service.models import PresetTouch
from phantomtouch.service.store import PatternStore
from tests.support.service import make_settings

DEVICE = DeviceProfile.default()
STILL = TouchPattern.model_validate(
    {"path": {"kind": "polyline", "points_cm": [[1.9, 7.0]]}, "duration_s": 3.0}
)


@pytest.fixture
def engine() -> Iterator[Engine]:
    with Engine(DEVICE, CaptureSink(DEVICE, realtime=True)) as engine:
        yield engine


@pytest.fixture
def admission(engine: Engine, tmp_path: Path) -> Iterator[Admission]:
    settings = make_settings(tmp_path, watchdog_s=0.2, max_contacts_per_connection=2)
    table = policy_table(settings)
    table["osc"] = table["osc"].replace(max_sources=4, max_sources_per_principal=4)
    store = PatternStore.open(tmp_path / "patterns.db")
    yield Admission(engine, table, store=store)
    store.close()


def open_osc(admission: Admission, port: int, host: str = "127.0.0.1") -> Handle:
    return admission.open("osc", f"{host}:{port}", principal=principal_for("osc", host=host))


def test_the_table_has_one_row_per_input_from_the_settings(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, watchdog_s=1.5, max_ws_message_bytes=4096)
    table = policy_table(settings)
    assert sorted(table) == sorted(KINDS)
    assert table["ws"].deadline_s == 1.5 and table["ws"].max_message_bytes == 4096
    assert table["rest"].deadline_s == math.inf and table["rest"].contacts_per_owner == 0
    assert table["ws"].quota.seconds == settings.max_voice_seconds_per_client
    with pytest.raises(ParameterError, match="max_work=0 must be > 0"):
        table["ws"].replace(max_work=0)


def test_a_principal_is_the_token_or_the_kind_and_host_and_never_shows_the_token() -> None:
    assert principal_for("osc", host="10.0.0.2") == "osc:10.0.0.2"
    token = "a-long-secret-token-0123"
    signed = principal_for("ws", host="10.0.0.2", token=token)
    assert signed == principal_for("rest", host="10.9.9.9", token=token)
    assert token not in signed and "/" not in signed
    long_host = "fe80:0000:0000:0000:0202:b3ff:fe1e:8329%eth0"
    assert len(principal_for("bhaptics-sdk2", host=long_host)) <= 40


def test_opening_a_source_twice_gives_its_one_handle_named_principal_slash_source(
    admission: Admission,
) -> None:
    first = open_osc(admission, 5000)
    assert open_osc(admission, 5000) is first
    assert first.owner == "osc:127.0.0.1/127.0.0.1:5000"
    with pytest.raises(ParameterError, match="kind='telnet'"):
        admission.open("telnet", "x", principal="telnet:x")  # type: ignore[arg-type]


def test_only_a_message_of_the_owner_renews_its_contacts(
    admission: Admission, engine: Engine
) -> None:
    quiet = admission.open("ws", "c1", principal="ws:127.0.0.1")
    chatty = admission.open("ws", "c2", principal="ws:127.0.0.1")
    quiet.down("a", 1.9, 7.0)
    deadline = time.monotonic() + 0.6
    while time.monotonic() < deadline:  # the other connection of the same host talks on
        assert chatty.receive(10).admitted
        time.sleep(0.02)
    assert not quiet.holds("a")  # 0.2 s deadline: released by the watchdog
    quiet.down("b", 1.9, 7.0)
    deadline = time.monotonic() + 0.6
    while time.monotonic() < deadline:
        quiet.receive(10)
        time.sleep(0.02)
    assert quiet.holds("b")


def test_size_contacts_and_protocol_are_refused_naming_the_limit(admission: Admission) -> None:
    ws = admission.open("ws", "c1", principal="ws:127.0.0.1")
    with pytest.raises(TooLargeError, match="over the limit"):
        ws.receive(ws.policy.max_message_bytes + 1)
    ws.down("a", 1.9, 7.0)
    with pytest.raises(ProtocolError, match="expected move or up, got down"):
        ws.down("a", 1.9, 7.0)
    ws.down("b", 1.9, 2.0)
    with pytest.raises(QuotaError, match="max_contacts_per_connection=2"):
        ws.down("c", 1.9, 3.0)
    with pytest.raises(ProtocolError, match="expected down, got move"):
        ws.move("c", 1.0, 1.0)
    assert ws.up("a") and not ws.up("a")
    with pytest.raises(ParameterError, match="voices: 3000 in one message; at most 2048"):
        ws.check_work(3000, field="voices")


def test_the_rate_of_a_principal_is_shared_by_its_sources(admission: Admission) -> None:
    rate = admission.policy("osc").messages_per_s
    now_s = time.monotonic()
    admitted = 0
    for port in range(4):  # each source within its own rate, the host twice it at most
        handle = open_osc(admission, 6000 + port)
        admitted += sum(handle.receive(1, now_s=now_s).admitted for _ in range(int(rate)))
    assert admitted == int(2 * rate)


def test_rotating_source_ports_never_take_the_slot_of_a_sender_that_holds_a_contact(
    admission: Admission,
) -> None:
    steady = open_osc(admission, 7000)
    steady.down("hand", 1.9, 7.0)
    yielded: list[str] = []
    for port in range(512):
        handle = admission.open(
            "osc",
            f"127.0.0.1:{10_000 + port}",
            principal="osc:127.0.0.1",
            on_yield=yielded.append,
        )
        handle.receive(16)
        if port % 50 == 0:
            steady.receive(16)
    assert steady.holds("hand") and not steady.closed
    assert len(admission.handles("osc")) == 4
    assert len(yielded) == 512 - 3 and "made room for a newcomer" in yielded[0]


def test_a_crowd_of_one_host_yields_to_another_host_and_never_the_other_way(
    admission: Admission,
) -> None:
    crowd = [open_osc(admission, 8000 + k) for k in range(3)]
    other = open_osc(admission, 9000, host="10.0.0.7")
    newcomer = open_osc(admission, 9001, host="10.0.0.8")  # full: the crowd's host yields
    assert crowd[0].closed and not other.closed and not newcomer.closed
    open_osc(admission, 8100)  # the crowd's host, full again: its own source yields
    assert not other.closed and not newcomer.closed and crowd[1].closed


def test_a_host_at_its_share_of_slots_passes_its_own_round_and_never_takes_anothers(
    engine: Engine, tmp_path: Path
) -> None:
    table = policy_table(make_settings(tmp_path))
    table["ws"] = table["ws"].replace(max_sources=2, max_sources_per_principal=2)
    admission = Admission(engine, table)
    a1 = admission.open("ws", "a1", principal="ws:10.0.0.1", now_s=1.0)
    a2 = admission.open("ws", "a2", principal="ws:10.0.0.1", now_s=2.0)
    b1 = admission.open("ws", "b1", principal="ws:10.0.0.2", now_s=3.0)  # host a yields one
    assert a1.closed and not a2.closed
    a3 = admission.open("ws", "a3", principal="ws:10.0.0.1", now_s=4.0)  # one apart
    assert a2.closed and not b1.closed and not a3.closed


def test_closing_releases_contacts_and_stops_touches_but_detached_ones(
    admission: Admission, engine: Engine
) -> None:
    ws = admission.open("ws", "c1", principal="ws:127.0.0.1")
    released: list[tuple[str, tuple[str, ...], str]] = []
    ws.on_released(lambda owner, contacts, reason: released.append((owner, contacts, reason)))
    ws.down("a", 1.9, 7.0)
    arrival = ws.receive(10).arrival
    assert arrival is not None
    own = ws.play_now(PresetTouch(preset="vr/stroke"), arrival=arrival)
    kept = ws.play_now(PresetTouch(preset="vr/stroke"), arrival=arrival, detached=True)
    ws.close()
    assert released == [(ws.owner, ("a",), "closed")]
    assert engine.job_state(own.job_id).state == "stopped"  # type: ignore[union-attr]
    assert engine.job_state(kept.job_id).state != "stopped"  # type: ignore[union-attr]
    assert ws not in admission.handles("ws")


def test_a_stop_voids_a_score_and_a_touch_sent_before_it_even_if_planned_after(
    admission: Admission, engine: Engine
) -> None:
    ws = admission.open("ws", "c1", principal="ws:127.0.0.1")
    arrival = ws.receive(10).arrival
    assert arrival is not None
    admission.stop_all()  # the stop comes while the message's work is being planned
    played = ws.play_score(Score((Voice(0.0, STILL), Voice(0.1, STILL)), 3.1), arrival=arrival)
    touch = ws.play_now(PresetTouch(preset="vr/stroke"), arrival=arrival)
    states = [engine.job_state(job).state for job in [*played.jobs, touch.job_id]]  # type: ignore[union-attr]
    assert states == ["stopped"] * 3
    time.sleep(0.3)
    assert engine.live_jobs(ws.owner) == 0
    later = ws.receive(10).arrival
    assert later is not None
    heard = ws.play_score(Score((Voice(0.0, STILL),), 3.0), arrival=later)
    assert engine.job_state(heard.jobs[0]).state != "stopped"  # type: ignore[union-attr]
    ws.close()


def test_a_score_with_more_voices_than_one_message_may_ask_for_is_refused_unplanned(
    admission: Admission, engine: Engine
) -> None:
    ws = admission.open("ws", "c1", principal="ws:127.0.0.1")
    arrival = ws.arrival()
    many = Score(tuple(Voice(0.0, STILL) for _ in range(ws.policy.max_work + 1)), 3.0)
    with pytest.raises(ParameterError, match="voices: 2049 in one message"):
        ws.play_score(many, arrival=arrival)
    assert engine.live_jobs(ws.owner) == 0 and np.isfinite(arrival.received_s)
