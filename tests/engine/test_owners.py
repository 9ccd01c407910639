"""The owner table: one owner per contact, deadlines, fair shares of contacts and voices."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from phantomtouch import DeviceProfile, EngineBusyError
from phantomtouch.engine import ContactSettings, Engine
from phantomtouch.engine.jobs import JobRecord, JobTable, Policy
from phantomtouch.engine.owners import ContactRecord, OwnerTable
from phantomtouch.output.sinks import CaptureSink

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
RELEASE_BLOCKS = round(0.08 * DEVICE.sample_rate_hz) // BLOCK + 2
WAIT_S = 10.0
"""Bound on waiting for a deadline thread that is starved by a busy machine."""


class Released:
    """A ``released`` listener that records what it is told."""

    def __init__(self) -> None:
        self.events: list[tuple[str, tuple[str, ...], str]] = []
        self.arrived = threading.Event()

    def __call__(self, owner: str, contacts: tuple[str, ...], reason: str) -> None:
        self.events.append((owner, contacts, reason))
        self.arrived.set()


def test_a_contact_whose_input_thread_died_is_released_by_its_deadline() -> None:
    sink = CaptureSink(DEVICE)
    released = Released()
    with Engine(DEVICE, sink) as engine:
        engine.subscribe_released(released)

        def input_thread() -> None:  # puts a contact down, then dies without a word
            engine.contact_down("input", "finger", 1.9, 7.2, deadline_s=0.2)

        thread = threading.Thread(target=input_thread)
        thread.start()
        thread.join()
        assert np.any(sink.pull(2)), "the contact vibrates"
        assert released.arrived.wait(WAIT_S), "released by its deadline"
        assert released.events == [("input", ("finger",), "watchdog")]
        assert engine.status().active_contacts == []
        sink.pull(RELEASE_BLOCKS)
        assert not np.any(sink.pull(2)), "silent after the release ramp"


def test_moves_keep_a_contact_down_past_its_deadline() -> None:
    released = Released()
    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        engine.subscribe_released(released, owner="input")
        engine.contact_down("input", "finger", 1.9, 7.2, deadline_s=1.5)
        for k in range(40):  # 2 s of moves, each well within the deadline
            engine.contact_move("input", "finger", 1.9, 7.2 - 0.1 * (k % 2))
            time.sleep(0.05)
        assert engine.holds("input", "finger")
        assert released.events == []
        assert released.arrived.wait(WAIT_S)
        assert released.events == [("input", ("finger",), "watchdog")]


def test_release_owner_publishes_the_reason_it_is_given() -> None:
    released = Released()
    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        engine.subscribe_released(released, owner="osc")
        engine.contact_down("osc", "a", 1.0, 1.0)
        engine.contact_down("osc", "b", 1.0, 2.0)
        engine.contact_down("other", "a", 1.0, 1.0)
        engine.release_owner("osc", "input died")
        assert released.events == [("osc", ("a", "b"), "input died")]
        assert engine.contacts_of("other") == ["a"]
        engine.stop_all()
        assert engine.contacts_of("other") == []


def test_a_full_table_takes_the_oldest_contact_of_the_largest_holder() -> None:
    released = Released()
    settings = ContactSettings(max_contacts=4)
    with Engine(DEVICE, CaptureSink(DEVICE), contact=settings) as engine:
        engine.subscribe_released(released)
        for finger in range(3):
            engine.contact_down("program", f"f{finger}", 1.0, 1.0 + finger)
        engine.contact_down("player", "p0", 1.0, 1.0)
        engine.contact_down("newcomer", "n0", 1.0, 1.0)
        assert released.events == [("program", ("f0",), "quota")]
        assert engine.contacts_of("program") == ["f1", "f2"]
        assert engine.contacts_of("newcomer") == ["n0"]
        with pytest.raises(EngineBusyError, match="max_contacts=4"):
            engine.contact_down("player", "p1", 1.0, 1.0)  # 2 vs 1: a take would only swap


def test_one_owner_may_not_take_from_an_owner_holding_one_fewer() -> None:
    table = OwnerTable(max_contacts=3)
    for owner, contact in (("a", "1"), ("a", "2"), ("b", "1")):
        table.put(owner, contact, ContactRecord(0, 0.0, 0.0))
    with pytest.raises(EngineBusyError):
        table.make_room("b")
    taken = table.make_room("c")
    assert taken is not None and taken[:2] == ("a", "1")
    assert len(table) == 2


def job(job_id: str, owner: str | None, first_frame: int) -> JobRecord:
    return JobRecord(
        plan=None,
        job_id=job_id,
        owner=owner,
        requested_start_frame=first_frame,
        frames=10_000,
        duration_s=1.0,
    )


def admit(table: JobTable, start_frame: int, owner: str, policy: Policy) -> list[JobRecord]:
    """Admit a job of ``owner`` where four voices may sound at once."""
    return table.admit(
        start_frame, 100, owner=owner, policy=policy, jobs=100, cost=0.0, budget=1.0, voices=4
    )


@pytest.mark.parametrize("policy", ["steal-oldest", "steal-quietest"])
def test_voices_are_stolen_from_the_largest_holder_only(policy: Policy) -> None:
    table = JobTable()
    table.add(job("victim", "client", 0))  # the oldest, and as quiet as any
    for k in range(3):
        table.add(job(f"flood{k}", "flood", 10 + k))
    victims = admit(table, 100, "flood-2", policy)
    assert [v.job_id for v in victims] == ["flood0"]


def test_an_owner_that_would_hold_the_most_steals_from_itself() -> None:
    table = JobTable()
    table.add(job("a0", "a", 0))
    table.add(job("a1", "a", 1))
    table.add(job("b0", "b", 2))
    table.add(job("b1", "b", 3))
    victims = admit(table, 100, "b", "steal-oldest")
    assert [v.job_id for v in victims] == ["b0"], "a holds 2, b would hold 3"
    table.add(job("c0", "c", 4))
    table.add(job("c1", "c", 5))
    table.add(job("c2", "c", 6))
    victims = admit(table, 100, "a", "steal-oldest")
    assert [v.job_id for v in victims] == ["a0", "c0", "a1", "b0"], (
        "a would hold 3 as c does: its own first, then whoever holds the most (oldest on a tie)"
    )


def test_an_owner_with_nothing_to_steal_at_the_start_is_refused() -> None:
    table = JobTable()
    table.add(job("small", "small", 0))
    for k in range(3):
        table.add(job(f"late{k}", "large", 50))  # the largest holder begins after the start
    with pytest.raises(EngineBusyError):
        admit(table, 10, "other", "steal-oldest")


def test_a_renewal_never_brings_a_deadline_forward() -> None:
    record = ContactRecord(0, 0.0, 0.0, term_s=1.0, deadline_s=10.0)
    record.renew(5.0)  # a message stamped with an older time than the touchdown's
    assert record.deadline_s == 10.0
    record.renew(9.5)
    assert record.deadline_s == 10.5
