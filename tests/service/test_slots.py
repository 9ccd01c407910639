"""The admission's connection half without an engine (phantomtouch/service/admission/
slots.py), as a fleet gateway holds its WebSocket connections: the ``fleet-gateway`` row's
size and rate, its slots by principal, and what yields when they are full."""

from __future__ import annotations

import pytest

from phantomtouch.service.admission import Slot, Slots, policy_table, principal_for
from phantomtouch.service.admission.policy import gateway_row
from phantomtouch.service.errors import SourcesFullError, TooLargeError
from phantomtouch.service.settings import ClientLimits, Settings

KIND = "fleet-gateway"


def gateway_slots(**limits: object) -> Slots[Slot]:
    """A gateway's slots under its row, with ``limits`` for its client limits."""
    fleet = policy_table(Settings.model_construct())["fleet"]
    row = gateway_row(ClientLimits(**limits), fleet)  # type: ignore[arg-type]
    return Slots({KIND: row}, make=Slot)


def remote(host: str) -> str:
    return principal_for("fleet", host=host)


def test_the_gateway_row_takes_its_connection_limits_and_the_nodes_fleet_row() -> None:
    limits = ClientLimits(max_ws_connections=5, max_ws_message_bytes=512, ws_messages_per_s=20.0)
    fleet = policy_table(Settings.model_construct())["fleet"]
    row = gateway_row(limits, fleet)
    assert (row.kind, row.max_sources, row.max_message_bytes, row.messages_per_s) == (
        KIND,
        5,
        512,
        20.0,
    )
    assert (row.contacts_per_owner, row.quota, row.max_work) == (
        fleet.contacts_per_owner,
        fleet.quota,
        fleet.max_work,
    )
    assert row.local_never_yields


def test_a_message_over_the_size_is_refused_by_name() -> None:
    slot = gateway_slots(max_ws_message_bytes=256).open(KIND, "c1", principal=remote("10.0.0.7"))
    assert slot.receive(256).admitted
    with pytest.raises(TooLargeError, match="300 bytes is over the limit of 256"):
        slot.receive(300)


def test_a_source_over_its_rate_is_dropped_and_its_host_shares_one_bucket() -> None:
    slots = gateway_slots(ws_messages_per_s=10.0)
    first = slots.open(KIND, "c1", principal=remote("10.0.0.7"))
    admitted = sum(first.receive(10, now_s=100.0).admitted for _ in range(30))
    assert admitted == 10  # one second of burst at 10 messages/s
    dropped = first.receive(10, now_s=100.0)
    assert not dropped.admitted and "per second from this source" in dropped.reason
    # The host's other connections share twice one source's rate, however many there are.
    others = [slots.open(KIND, f"c{k}", principal=remote("10.0.0.7")) for k in range(2, 12)]
    more = sum(o.receive(10, now_s=100.0).admitted for o in others for _ in range(5))
    assert more == 10
    stranger = slots.open(KIND, "s1", principal=remote("10.0.0.8"))
    assert stranger.receive(10, now_s=100.0).admitted


def test_a_full_gateway_makes_room_the_silent_longest_of_the_crowded_host_yields() -> None:
    slots = gateway_slots(max_ws_connections=4, max_ws_connections_per_address=4)
    yielded: dict[str, str] = {}
    crowd = [
        slots.open(
            KIND,
            f"c{k}",
            principal=remote("10.0.0.66"),
            on_yield=lambda reason, k=k: yielded.setdefault(f"c{k}", reason),
            now_s=10.0 + k,
        )
        for k in range(4)
    ]
    crowd[0].receive(10, now_s=20.0)  # c0 spoke last; c1 is the one silent longest
    newcomer = slots.open(KIND, "n1", principal=remote("10.0.0.7"), now_s=21.0)
    assert list(yielded) == ["c1"] and "made room for a newcomer" in yielded["c1"]
    assert crowd[1].closed and not newcomer.closed
    assert [s.source for s in slots.handles(KIND)] == ["c0", "c2", "c3", "n1"]


def test_loopback_connections_never_yield_and_a_remote_one_is_refused_when_they_fill_it() -> None:
    slots = gateway_slots(max_ws_connections=2)
    local = remote("127.0.0.1")
    for k in range(3):
        slots.open(KIND, f"l{k}", principal=local, local=True)
    with pytest.raises(SourcesFullError, match="none may yield"):
        slots.open(KIND, "r1", principal=remote("10.0.0.7"))


def test_a_closed_slot_frees_its_place_and_is_opened_anew() -> None:
    slots = gateway_slots(max_ws_connections=1, max_ws_connections_per_address=1)
    first = slots.open(KIND, "c1", principal=remote("10.0.0.7"))
    assert slots.find(first.owner) is first
    first.close()
    assert slots.handles(KIND) == [] and slots.find(first.owner) is None
    again = slots.open(KIND, "c1", principal=remote("10.0.0.7"))
    assert again is not first and not again.closed
