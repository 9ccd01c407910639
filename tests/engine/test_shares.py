"""The one fair-share rule (phantomtouch/engine/shares.py) and the tables that apply it:
contact slots, voices, and a job history kept per owner (docs/owners.md)."""

from __future__ import annotations

import itertools

import pytest

from phantomtouch.engine.jobs import JobRecord, JobTable, Policy
from phantomtouch.engine.owners import ContactRecord, OwnerTable
from phantomtouch.engine.shares import yielding
from phantomtouch.errors import EngineBusyError


@pytest.mark.parametrize(
    ("held", "owner", "givers"),
    [
        ({"a": 1, "b": 1}, "new", ["a", "b"]),  # a newcomer holding 0 takes from holders of 1
        ({"a": 3, "b": 1}, "new", ["a"]),  # ... from the largest holder
        ({"a": 2, "me": 1}, "me", []),  # one apart: a take would only swap the shortfall
        ({"a": 3, "me": 1}, "me", ["a"]),  # two apart: the take evens the shares out
        ({"a": 3, "b": 3, "me": 1}, "me", ["a", "b"]),
        ({"me": 5}, "me", []),  # nobody else holds anything
        ({}, "me", []),
    ],
)
def test_who_yields_a_slot(held: dict[str, int], owner: str, givers: list[str]) -> None:
    assert yielding(held, owner) == givers


@pytest.mark.parametrize(
    ("held", "owner", "givers"),
    [
        # 200 sources of one program hold one voice each; a second program's one voice
        # never yields to them: they share what their program holds
        (
            {**{f"osc:h/{k}": 1 for k in range(200)}, "ws:h/1": 1},
            "osc:h/new",
            [f"osc:h/{k}" for k in range(200)],
        ),
        ({**{f"osc:h/{k}": 1 for k in range(3)}, "ws:h/1": 1}, "osc:h/0", []),
        # a program holding nothing takes from the program holding the most, and there
        # from the source holding the most
        ({"osc:h/1": 1, "osc:h/2": 3, "ws:h/1": 1}, "rest:h/1", ["osc:h/2"]),
        # one apart between programs, the owners of the asker's program share among
        # themselves
        ({"osc:h/1": 2, "ws:h/1": 3}, "osc:h/2", ["osc:h/1"]),
        ({"osc:h/1": 1, "ws:h/1": 2}, "osc:h/1", []),
    ],
)
def test_shares_go_first_among_principals_then_among_their_owners(
    held: dict[str, int], owner: str, givers: list[str]
) -> None:
    assert yielding(held, owner) == givers


def test_every_owner_asking_once_ends_with_one_slot_whoever_asked_first() -> None:
    """However many owners ask, each in turn, the slots pass to whoever holds none: no
    owner ever holds two while another that asked holds none."""
    table = OwnerTable(max_contacts=4)
    handles = itertools.count(1)
    for k in range(9):
        owner = f"o{k}"
        taken = table.make_room(owner)
        table.put(owner, "c", ContactRecord(next(handles), 0.0, 0.0))
        counts = [len(table.held(f"o{j}")) for j in range(k + 1)]
        assert max(counts) == 1 and sum(counts) == min(4, k + 1)
        if k >= 4:  # the oldest holder yielded its contact
            assert taken is not None and taken[:2] == (f"o{k - 4}", "c")


def test_an_owner_one_short_of_the_largest_is_refused_busy() -> None:
    table = OwnerTable(max_contacts=3)
    for handle, (owner, contact) in enumerate([("a", "1"), ("a", "2"), ("me", "1")], 1):
        table.put(owner, contact, ContactRecord(handle, 0.0, 0.0))
    with pytest.raises(EngineBusyError, match="no other owner holds two more"):
        table.make_room("me")


def sounding(job_id: str, owner: str, first_frame: int) -> JobRecord:
    job = JobRecord(None, job_id, owner, first_frame, frames=10_000, duration_s=1.0)
    job.state = "playing"
    job.start_frame = first_frame
    return job


def test_a_newcomer_steals_the_oldest_voice_of_a_crowd_of_single_holders() -> None:
    table = JobTable()
    for k in range(4):
        table.add(sounding(f"j{k}", f"o{k}", first_frame=10 + k))

    def admit(owner: str, policy: Policy = "steal-oldest") -> list[str]:
        victims = table.admit(
            100, 1000, jobs=100, cost=0.0, budget=1.0, voices=4, policy=policy, owner=owner
        )
        return [victim.job_id for victim in victims]

    assert admit("new") == ["j0"]
    with pytest.raises(EngineBusyError):  # a holder of one asking for a second is refused
        admit("o1", "refuse")
    assert admit("o1") == ["j1"]  # ... or, stealing, its own oldest makes room


def test_a_flood_of_jobs_evicts_its_own_history_first() -> None:
    table = JobTable(history=3)
    mine = JobRecord(None, "mine", "me", 0, 10, 0.1)
    table.add(mine)
    table.retire(mine)
    flood = [JobRecord(None, f"f{k}", "flood", 0, 10, 0.1) for k in range(50)]
    for job in flood:
        table.add(job)
        table.retire(job)
    assert table.get("mine") is mine
    assert [table.get(f"f{k}") is not None for k in (0, 46, 47, 48, 49)] == [
        False,
        False,
        True,
        True,
        True,
    ]


def test_the_history_over_every_owner_is_bounded_the_largest_holder_gives_first() -> None:
    table = JobTable(history=2)  # at most 10 * 2 = 20 jobs over every owner
    for owner in range(25):
        for k in range(2 if owner == 0 else 1):
            job = JobRecord(None, f"{owner}-{k}", f"o{owner}", 0, 10, 0.1)
            table.add(job)
            table.retire(job)
    kept = [job for job in ["0-1", *(f"{o}-0" for o in range(25))] if table.get(job)]
    # o0 held two: it gave first; then, all tied at one, the owners heard first gave
    assert kept == [f"{o}-0" for o in range(5, 25)]
