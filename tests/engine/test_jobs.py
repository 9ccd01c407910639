"""The job table keeps every live job and a bounded history of finished ones."""

from __future__ import annotations

import pytest

from phantomtouch import DeviceProfile, EngineBusyError, ParameterError, TouchPattern
from phantomtouch.engine import Engine
from phantomtouch.engine.jobs import JobRecord, JobTable, OwnerQuota, QuotaRefused
from phantomtouch.engine.plans import resolve_plan
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.renderer import plan


def record(job_id: str) -> JobRecord:
    return JobRecord(
        plan=None, job_id=job_id, owner=None, requested_start_frame=0, frames=10, duration_s=0.1
    )


def test_finished_jobs_are_kept_up_to_the_history_limit() -> None:
    table = JobTable(history=3)
    records = [record(f"j{k}") for k in range(5)]
    for r in records:
        table.add(r)
    assert len(table) == 5
    for r in records:
        r.state = "finished"
        table.retire(r)
    assert len(table) == 0
    assert [table.get(f"j{k}") is not None for k in range(5)] == [False, False, True, True, True]


def test_a_job_asked_to_stop_is_no_longer_live_but_still_answers() -> None:
    table = JobTable()
    live, stopping = record("live"), record("stopping")
    table.add(live)
    table.add(stopping)
    table.mark_stopped(stopping)
    assert len(table) == 1 and table.get("stopping") is stopping
    assert stopping.snapshot().state == "stopped"
    table.stop_all()
    assert len(table) == 0 and live.state == "stopped"


def test_resolve_plan_refuses_plans_of_other_devices_and_other_types() -> None:
    pattern = TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[1, 1], [1, 5]]}, "speed_cm_s": 5}
    )
    device = DeviceProfile.default()
    assert resolve_plan(pattern, device).frames == plan(pattern, device).frames
    with pytest.raises(ParameterError, match="Plan for device"):
        resolve_plan(plan(pattern, DeviceProfile(sample_rate_hz=44100)), device)
    # the block size changes no sample of a plan: one made at another block is this device's
    at_period = plan(pattern, DeviceProfile(block_frames=128))
    assert resolve_plan(at_period, device) is at_period
    with pytest.raises(ParameterError, match="got dict"):
        resolve_plan({"path": {}}, device)  # type: ignore[arg-type]


def costing(job_id: str, cost: float, first_frame: int) -> JobRecord:
    job = JobRecord(
        plan=None,
        job_id=job_id,
        owner=None,
        requested_start_frame=first_frame,
        frames=1000,
        duration_s=1.0,
        cost=cost,
    )
    job.state = "playing"
    return job


def test_admission_sums_what_the_sounding_jobs_cost_against_the_budget() -> None:
    table = JobTable()
    # two voices rendered in the callback (1/8 of a block each) and five prerendered (1/20)
    for k, cost in enumerate([0.125, 0.125, 0.05, 0.05, 0.05, 0.05, 0.05]):
        table.add(costing(f"j{k}", cost, first_frame=k))
    limits = {"jobs": 100, "budget": 0.5, "voices": 64}
    assert table.admit(10, 100, cost=0.0, policy="refuse", **limits) == []  # 0.5: fits
    with pytest.raises(EngineBusyError, match="the voice budget allows 10 such voices"):
        table.admit(10, 100, cost=0.05, policy="refuse", **limits)
    # the oldest is stolen, and no more than makes room: it alone frees 1/8
    victims = table.admit(10, 100, cost=0.1, policy="steal-oldest", **limits)
    assert [v.job_id for v in victims] == ["j0"]
    # a voice costing the whole budget needs every other one gone
    victims = table.admit(10, 100, cost=0.5, policy="steal-oldest", **limits)
    assert len(victims) == 7
    # the voice count bounds too, whatever the costs
    with pytest.raises(EngineBusyError, match="at most 7"):
        table.admit(10, 100, cost=0.0, policy="refuse", jobs=100, budget=0.5, voices=7)


def test_the_front_counts_an_owners_quota_in_its_job_table() -> None:
    """Two 1 s touches fill an owner's 2 s; a third waits until one is stopped, and
    another owner is not counted against it."""
    device = DeviceProfile.default()
    one_second = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1, 1]]},
            "duration_s": 1.0,
            "fade_in_s": 0,
            "fade_out_s": 0,
        }
    )
    quota = OwnerQuota(voices=10, seconds=2.0)
    with Engine(device, CaptureSink(device), voice_cost=1e-4) as engine:
        first = engine.schedule(one_second, owner="a", quota=quota)
        engine.schedule(one_second, owner="a", quota=quota)
        with pytest.raises(QuotaRefused) as refused:
            engine.schedule(one_second, owner="a", quota=quota)
        assert (refused.value.limit, refused.value.jobs) == ("seconds", 2)
        assert refused.value.held_s == pytest.approx(2.0)
        engine.schedule(one_second, owner="b", quota=quota)
        assert engine.stop(first.job_id)
        engine.schedule(one_second, owner="a", quota=quota)
        with pytest.raises(ParameterError, match="owner"):
            engine.schedule(one_second, quota=quota)


def test_touches_as_soon_as_possible_fill_a_quota_of_their_durations() -> None:
    """Two 2 h touches fill an owner's 4 h, asked for at the same frame: the block the
    engine takes to begin a touch it renders in the callback is not counted against them."""
    device = DeviceProfile.default()
    hours = TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[1, 1], [2, 2]]}, "duration_s": 7200.0}
    )
    quota = OwnerQuota(voices=10, seconds=14_400.0)
    with Engine(device, CaptureSink(device), voice_cost=1e-4) as engine:
        first = engine.schedule(hours, owner="a", quota=quota)
        assert first.start_frame > 0, "a touch rendered in the callback begins a block later"
        engine.schedule(hours, owner="a", quota=quota)
        with pytest.raises(QuotaRefused) as refused:
            engine.schedule(hours, owner="a", quota=quota)
        assert refused.value.held_s == pytest.approx(14_400.0)
