"""The job table keeps every live job and a bounded history of finished ones."""

from __future__ import annotations

import pytest

from phantomtouch import DeviceProfile, ParameterError, TouchPattern
from phantomtouch.engine.jobs import JobRecord, JobTable, resolve_plan
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
        resolve_plan(plan(pattern, DeviceProfile(block_frames=128)), device)
    with pytest.raises(ParameterError, match="got dict"):
        resolve_plan({"path": {}}, device)  # type: ignore[arg-type]
