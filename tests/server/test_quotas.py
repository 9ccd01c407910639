"""Fair shares: per-client voices and voice-seconds ahead, counted in the engine's job
table on frames the test picks (one frame a second), answered as the service does."""

from __future__ import annotations

import itertools

import pytest

from phantomtouch.engine.jobs import JobRecord, JobTable, OwnerQuota, QuotaRefused
from phantomtouch.service.errors import QuotaError
from phantomtouch.service.scheduling import quota_error

JOB_IDS = itertools.count()


def play(
    table: JobTable, quota: OwnerQuota, owner: str, now_s: int, start_s: int, s: int
) -> JobRecord:
    """Admit a job of ``s`` frames from ``start_s`` of ``owner`` (refusals as the service
    answers them), with ``now_s`` the next block's frame, and add it."""
    try:
        table.check_quota(owner, quota, start_s, s, next_frame=now_s, rate_hz=1)
    except QuotaRefused as refused:
        raise quota_error(refused, float(s)) from refused
    job = JobRecord(None, f"{owner}{next(JOB_IDS)}", owner, max(start_s, now_s), s, float(s))
    table.add(job)
    return job


def holding(table: JobTable, owner: str, now_s: int) -> tuple[int, float]:
    """The owner's jobs not over at ``now_s``, and their seconds ahead (what a refusal says)."""
    with pytest.raises(QuotaRefused) as refused:
        table.check_quota(owner, OwnerQuota(1_000_000, 0.0), now_s, 1, next_frame=now_s, rate_hz=1)
    return refused.value.jobs, refused.value.held_s


def test_voices_per_client_refuse_the_next_and_leave_others_alone() -> None:
    table, quota = JobTable(), OwnerQuota(voices=3, seconds=1e6)
    for _ in range(3):
        play(table, quota, "a", 0, 0, 10)
    with pytest.raises(QuotaError, match="max_voices_per_client=3") as refused:
        play(table, quota, "a", 1, 1, 1)
    assert refused.value.field == "voices"
    play(table, quota, "b", 1, 1, 1)
    play(table, quota, "a", 10, 10, 1)
    assert holding(table, "a", 10) == (1, 1.0), "ended touches no longer count"


def test_long_touches_count_by_the_time_they_hold() -> None:
    table, quota = JobTable(), OwnerQuota(voices=100, seconds=14_400.0)
    for _ in range(2):
        play(table, quota, "a", 0, 0, 7200)
    with pytest.raises(QuotaError, match="max_voice_seconds_per_client=14400 s"):
        play(table, quota, "a", 0, 0, 1)
    assert holding(table, "a", 3600) == (2, 7200.0), "they hold less as they play"
    play(table, quota, "a", 3600, 3600, 7200)


def test_a_start_ahead_counts_from_now() -> None:
    table, quota = JobTable(), OwnerQuota(voices=10, seconds=100.0)
    with pytest.raises(QuotaError):  # 60 s from now plus 50 s of touch: 110 s ahead
        play(table, quota, "a", 0, 60, 50)


def test_touches_stopped_early_no_longer_count() -> None:
    table, quota = JobTable(), OwnerQuota(voices=2, seconds=1e6)
    table.mark_stopped(play(table, quota, "a", 0, 0, 30))
    play(table, quota, "a", 0, 0, 30)
    play(table, quota, "a", 1, 1, 1)
    assert holding(table, "a", 1)[0] == 2


def test_touches_that_just_fit_still_fit_once_scheduled_a_block_later() -> None:
    table, quota = JobTable(), OwnerQuota(voices=10, seconds=14_400.0)
    play(table, quota, "a", 0, 0, 7200)
    play(table, quota, "a", 1, 1, 7200)  # asked a block later: the first holds 7199 s
    assert holding(table, "a", 1) == (2, 14_399.0)
