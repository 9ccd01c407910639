"""The flood rule of a WebSocket connection, on a clock the test drives."""

from __future__ import annotations

from phantomtouch.service.flood import FloodGuard


def test_within_the_rate_nothing_is_dropped() -> None:
    guard = FloodGuard(100.0)
    start_s = guard._stamp_s
    assert all(guard.admit(start_s + k / 100.0) for k in range(1000))  # 10 s at the rate
    assert guard.dropped == 0


def test_a_burst_past_the_bucket_is_dropped_but_not_a_flood_for_long() -> None:
    guard = FloodGuard(100.0)
    start_s = guard._stamp_s
    admitted = [guard.admit(start_s) for _ in range(150)]
    assert sum(admitted) == 100, "one second of burst"
    assert guard.dropped == 50 and guard.flood_started is False
    assert guard.admit(start_s + 1.0), "calm for 1 s: the flood is over"
    assert not guard.sustained(start_s + 2.0)


def test_a_burst_admitted_after_a_stall_does_not_end_a_flood() -> None:
    """The server held up for 0.3 s: the refilled bucket admits a burst of the client's
    queued messages, and the flood goes on."""
    guard = FloodGuard(100.0, close_after_s=1.0)
    start_s = guard._stamp_s
    for k in range(300):
        guard.admit(start_s + k / 1000.0)
    admitted = sum(guard.admit(start_s + 0.6) for _ in range(100))
    assert 25 <= admitted <= 35, "0.3 s of refill"
    flooding = [guard.admit(start_s + 0.6 + k / 1000.0) for k in range(600)]
    assert not all(flooding) and guard.sustained(start_s + 1.2)


def test_a_second_of_messages_at_the_rate_ends_a_flood() -> None:
    guard = FloodGuard(100.0, close_after_s=1.0)
    start_s = guard._stamp_s
    for _ in range(101):
        guard.admit(start_s)
    assert all(guard.admit(start_s + 0.0101 * (k + 1)) for k in range(100))
    end_s = start_s + 0.0101 * 100
    while guard.admit(end_s):
        pass
    assert guard.flood_started, "the next drop begins a new flood"
    assert not guard.sustained(end_s)


def test_a_flood_the_bucket_keeps_admitting_from_is_still_sustained() -> None:
    """At ten times the rate the refilled bucket admits one message in ten; that does not
    end the flood (the rule the old refusal streak broke)."""
    guard = FloodGuard(100.0, close_after_s=1.0)
    start_s = guard._stamp_s
    results = [guard.admit(start_s + k / 1000.0) for k in range(1200)]
    first_drop = results.index(False)
    assert results[first_drop + 1 :].count(True) > 50, "admitted now and then"
    assert guard.sustained(start_s + first_drop / 1000.0 + 1.0)
    assert not guard.sustained(start_s + first_drop / 1000.0 + 0.9)


def test_only_the_first_drop_of_a_flood_starts_it() -> None:
    guard = FloodGuard(10.0)
    start_s = guard._stamp_s
    for _ in range(10):
        guard.admit(start_s)
    assert not guard.admit(start_s) and guard.flood_started
    assert not guard.admit(start_s + 0.001) and not guard.flood_started
    admitted = 0
    while guard.admit(start_s + 1.0):  # calm for 1 s: the flood is over, 10 refilled
        admitted += 1
    assert admitted == 10 and guard.flood_started, "the next drop begins a new flood"
