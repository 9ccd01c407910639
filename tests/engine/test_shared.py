"""Shared memory between the host and the engine process: the clock and move slots."""

from __future__ import annotations

import math
import sys
import threading

import pytest

from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.shared import MoveSlots, SharedClock

RATE = 48000


def test_the_shared_clock_maps_frames_and_times_as_the_engine_clock_does() -> None:
    shared = SharedClock(RATE)
    clock = SampleClock(RATE, now_s=50.0, publish=shared.publish)
    clock.output_latency_s = 0.007
    for k in range(1, 400):  # jittered callbacks move the anchor
        clock.observe(256 * k, 50.0 + 256 * k / RATE + 0.0003 * (k % 5))
    for frame in (0, 12_345, 256 * 399, 10 * RATE):
        assert shared.time_at(frame) == clock.time_at(frame)
    for time_s in (50.0, 50.5, 51.123456, 60.0):
        assert shared.frames_at(time_s) == clock.frames_at(time_s)
    clock.restart(7, 99.0)
    assert shared.anchor() == (7, 99.0, 0.007)


def test_readers_never_see_half_a_write() -> None:
    interval_s = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads as often as possible
    shared = SharedClock(RATE)
    slots = MoveSlots(1)
    slot, generation = slots.allocate() or (0, 0)
    slots.bind(slot, generation, "c", "1")
    done = threading.Event()

    def writer() -> None:
        for k in range(1, 30_000):
            shared.publish(k, k * 0.5, k * 0.25)
            slots.write(slot, generation, float(k), 2.0 * k, None, None)
        done.set()

    thread = threading.Thread(target=writer)
    try:
        thread.start()
        clocks, moves = 0, []
        while not done.is_set():
            frame, anchor_s, latency_s = shared.anchor()
            assert (anchor_s, latency_s) == (frame * 0.5, frame * 0.25)
            clocks += 1
            slots.drain(lambda owner, contact, x, y, intensity, at: moves.append((x, y)))
        thread.join()
    finally:
        sys.setswitchinterval(interval_s)
    assert clocks > 10 and moves and all(y == 2.0 * x for x, y in moves)


def posted(slots: MoveSlots) -> list[tuple[object, ...]]:
    got: list[tuple[object, ...]] = []
    slots.drain(lambda *args: got.append(args))
    return got


def test_only_the_newest_position_of_a_bound_slot_is_posted_once() -> None:
    slots = MoveSlots(4)
    taken = slots.allocate()
    assert taken is not None
    slot, generation = taken
    slots.write(slot, generation, 1.0, 2.0, None, None)
    assert posted(slots) == []  # not bound yet: the touchdown is not through
    slots.bind(slot, generation, "client", "finger")
    slots.write(slot, generation, 1.5, 2.5, 0.5, None)
    slots.write(slot, generation, 1.7, 2.7, None, 4800)
    assert posted(slots) == [("client", "finger", 1.7, 2.7, None, 4800)]
    assert posted(slots) == []  # applied once


def test_a_slot_that_changes_hands_never_posts_what_it_held_before() -> None:
    slots = MoveSlots(1)
    slot, old = slots.allocate() or (0, 0)
    slots.bind(slot, old, "a", "1")
    slots.write(slot, old, 1.0, 1.0, None, None)
    slots.unbind("a", "1")
    slots.release(slot)
    assert posted(slots) == []
    again = slots.allocate()
    assert again is not None and again[0] == slot and again[1] != old
    slots.write(slot, old, 3.0, 3.0, None, None)  # late from the earlier contact
    slots.bind(slot, again[1], "b", "1")
    assert posted(slots) == []
    slots.write(slot, again[1], 2.0, 9.0, None, None)
    assert posted(slots) == [("b", "1", 2.0, 9.0, None, None)]


def test_a_row_caught_mid_write_waits_for_the_next_block() -> None:
    slots = MoveSlots(2)
    slot, generation = slots.allocate() or (0, 0)
    slots.bind(slot, generation, "c", "1")
    row = slots._rows[slot]
    row[0] += 1.0  # the host has begun to write
    row[2], row[3], row[4], row[5] = 1.0, 2.0, math.nan, math.nan
    assert posted(slots) == []
    row[1] = generation
    row[0] += 1.0
    assert posted(slots) == [("c", "1", 1.0, 2.0, None, None)]


def test_slots_run_out_and_come_back() -> None:
    slots = MoveSlots(2)
    first, second = slots.allocate(), slots.allocate()
    assert first is not None and second is not None and slots.allocate() is None
    slots.release(first[0])
    assert slots.allocate() == (first[0], pytest.approx(3))
