"""Fair shares: per-client voices and voice-seconds ahead, on server times the test picks."""

from __future__ import annotations

import pytest

from phantomtouch.service.errors import QuotaError
from phantomtouch.service.quotas import VoiceLedger


def playing(job_id: str) -> bool:
    return True


def test_voices_per_client_refuse_the_next_and_leave_others_alone() -> None:
    ledger = VoiceLedger(voices_per_client=3, voice_seconds_per_client=1e6)
    for k in range(3):
        hold = ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=10.0, still_playing=playing)
        ledger.confirm(hold, f"a{k}", 10.0)
    with pytest.raises(QuotaError, match="max_voices_per_client=3") as refused:
        ledger.reserve("a", now_s=1.0, start_s=1.0, duration_s=1.0, still_playing=playing)
    assert refused.value.field == "voices"
    ledger.reserve("b", now_s=1.0, start_s=1.0, duration_s=1.0, still_playing=playing)
    ledger.reserve("a", now_s=10.0, start_s=10.0, duration_s=1.0, still_playing=playing)
    assert ledger.holding("a", 10.0) == (1, 1.0), "ended touches no longer count"


def test_long_touches_count_by_the_time_they_hold() -> None:
    ledger = VoiceLedger(voices_per_client=100, voice_seconds_per_client=14_400.0)
    for k in range(2):
        hold = ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=7200.0, still_playing=playing)
        ledger.confirm(hold, f"long{k}", 7200.0)
    with pytest.raises(QuotaError, match="max_voice_seconds_per_client=14400 s"):
        ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=1.0, still_playing=playing)
    assert ledger.holding("a", 3600.0) == (2, 7200.0), "they hold less as they play"
    ledger.reserve("a", now_s=3600.0, start_s=3600.0, duration_s=7200.0, still_playing=playing)


def test_a_start_ahead_counts_from_now() -> None:
    ledger = VoiceLedger(voices_per_client=10, voice_seconds_per_client=100.0)
    with pytest.raises(QuotaError):  # 60 s from now plus 50 s of touch: 110 s ahead
        ledger.reserve("a", now_s=0.0, start_s=60.0, duration_s=50.0, still_playing=playing)


def test_touches_stopped_early_are_forgotten_when_the_quota_is_reached() -> None:
    ledger = VoiceLedger(voices_per_client=2, voice_seconds_per_client=1e6)
    for job_id in ("x", "y"):
        hold = ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=30.0, still_playing=playing)
        ledger.confirm(hold, job_id, 30.0)
    asked: list[str] = []

    def only_y(job_id: str) -> bool:
        asked.append(job_id)
        return job_id == "y"

    ledger.reserve("a", now_s=1.0, start_s=1.0, duration_s=1.0, still_playing=only_y)
    assert sorted(asked) == ["x", "y"]
    assert ledger.holding("a", 1.0)[0] == 2


def test_a_cancelled_reservation_gives_its_place_back() -> None:
    ledger = VoiceLedger(voices_per_client=1, voice_seconds_per_client=1e6)
    hold = ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=5.0, still_playing=playing)
    ledger.cancel(hold)
    assert ledger.holding("a", 0.0) == (0, 0.0)
    ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=5.0, still_playing=playing)


def test_touches_that_just_fit_still_fit_once_scheduled_a_little_later() -> None:
    ledger = VoiceLedger(voices_per_client=10, voice_seconds_per_client=14_400.0)
    for k in range(2):
        hold = ledger.reserve("a", now_s=0.0, start_s=0.0, duration_s=7200.0, still_playing=playing)
        ledger.confirm(hold, f"long{k}", 0.02 + 7200.0)  # started 20 ms after the request
    assert ledger.holding("a", 0.0) == (2, 14_400.0)
