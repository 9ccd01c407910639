"""Shared memory between the host and the engine process: the clock, move slots and
mapped blocks.

Every behaviour is tested with both guards: the sequence locks x86 uses and the locks
used elsewhere (forced here with ``locked=True`` or ``PHANTOMTOUCH_SHARED_LOCKS=1``).
"""

from __future__ import annotations

import math
import multiprocessing
import sys
import threading
from typing import Any

import numpy as np
import pytest

from phantomtouch.engine import shared as shared_module
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.shared import (
    LOCKS_VARIABLE,
    MappedBlocks,
    MoveSlots,
    SharedBuffer,
    SharedClock,
    StatusBlock,
    sequence_locks_are_safe,
    unlink_block,
    write_block,
)

RATE = 48000
CHANNELS = 2
"""Gains per slot here: a position's two gains stand in for the device's eight."""


def gains(a: float, b: float) -> np.ndarray:
    return np.array([a, b], dtype=np.float32)


@pytest.fixture(params=[False, True], ids=["sequence-lock", "lock"])
def locked(request: pytest.FixtureRequest) -> bool:
    value: bool = request.param
    return value


def test_the_shared_clock_maps_frames_and_times_as_the_engine_clock_does(locked: bool) -> None:
    shared = SharedClock(RATE, locked=locked)
    assert shared.locked is locked
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


def test_readers_never_see_half_a_write(locked: bool) -> None:
    interval_s = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads as often as possible
    shared = SharedClock(RATE, locked=locked)
    slots = MoveSlots(1, CHANNELS, locked=locked)
    slot, generation = slots.allocate() or (0, 0)
    slots.bind(slot, generation, 1)
    done = threading.Event()

    def writer() -> None:
        for k in range(1, 30_000):
            shared.publish(k, k * 0.5, k * 0.25)
            slots.write(slot, generation, gains(float(k), 2.0 * k), None, None)
        done.set()

    thread = threading.Thread(target=writer)
    try:
        thread.start()
        clocks, moves = 0, []
        while not done.is_set():
            frame, anchor_s, latency_s = shared.anchor()
            assert (anchor_s, latency_s) == (frame * 0.5, frame * 0.25)
            clocks += 1
            slots.drain(lambda contact, g, intensity, at: moves.append((float(g[0]), float(g[1]))))
        thread.join()
    finally:
        sys.setswitchinterval(interval_s)
    assert clocks > 10 and moves and all(y == 2.0 * x for x, y in moves)


def posted(slots: MoveSlots) -> list[tuple[object, ...]]:
    got: list[tuple[object, ...]] = []
    slots.drain(lambda contact, g, intensity, at: got.append((contact, *g.tolist(), intensity, at)))
    return got


def test_only_the_newest_position_of_a_bound_slot_is_posted_once(locked: bool) -> None:
    slots = MoveSlots(4, CHANNELS, locked=locked)
    taken = slots.allocate()
    assert taken is not None
    slot, generation = taken
    slots.write(slot, generation, gains(1.0, 2.0), None, None)
    assert posted(slots) == []  # not bound yet: the touchdown is not through
    slots.bind(slot, generation, 7)
    slots.write(slot, generation, gains(1.5, 2.5), 0.5, None)
    slots.write(slot, generation, gains(1.75, 2.75), None, 4800)
    assert posted(slots) == [(7, 1.75, 2.75, None, 4800)]
    assert posted(slots) == []  # applied once


def test_a_position_written_before_the_slot_is_bound_is_posted_once_it_is(locked: bool) -> None:
    slots = MoveSlots(128, CHANNELS, locked=locked)
    first, second = slots.allocate() or (0, 0), slots.allocate() or (0, 0)
    slots.bind(first[0], first[1], 1)
    slots.write(second[0], second[1], gains(0.5, 1.5), None, None)  # its touchdown in transit
    slots.write(first[0], first[1], gains(2.0, 3.0), None, None)
    assert posted(slots) == [(1, 2.0, 3.0, None, None)]  # the bound slot alone
    slots.bind(second[0], second[1], 2)
    assert posted(slots) == [(2, 0.5, 1.5, None, None)]
    assert posted(slots) == []


def test_a_slot_that_changes_hands_never_posts_what_it_held_before(locked: bool) -> None:
    slots = MoveSlots(1, CHANNELS, locked=locked)
    slot, old = slots.allocate() or (0, 0)
    slots.bind(slot, old, 1)
    slots.write(slot, old, gains(1.0, 1.0), None, None)
    slots.unbind((1,))
    slots.release(slot)
    assert posted(slots) == []
    again = slots.allocate()
    assert again is not None and again[0] == slot and again[1] != old
    slots.write(slot, old, gains(3.0, 3.0), None, None)  # late from the earlier contact
    slots.bind(slot, again[1], 2)
    assert posted(slots) == []
    slots.write(slot, again[1], gains(2.0, 9.0), None, None)
    assert posted(slots) == [(2, 2.0, 9.0, None, None)]


def test_a_row_caught_mid_write_waits_for_the_next_block() -> None:
    slots = MoveSlots(2, CHANNELS, locked=False)
    slot, generation = slots.allocate() or (0, 0)
    slots.bind(slot, generation, 1)
    row = np.frombuffer(slots.raw.values, dtype=np.float64).reshape(2, -1)[slot]
    row[0] += 1.0  # the host has begun to write
    row[2], row[3], row[4], row[5] = math.nan, math.nan, 1.0, 2.0
    assert posted(slots) == []
    row[1] = generation
    row[0] += 1.0
    assert posted(slots) == [(1, 1.0, 2.0, None, None)]


def test_with_a_lock_the_callback_skips_a_block_while_the_host_writes() -> None:
    slots = MoveSlots(2, CHANNELS, locked=True)
    slot, generation = slots.allocate() or (0, 0)
    slots.bind(slot, generation, 1)
    slots.write(slot, generation, gains(1.0, 2.0), None, None)
    lock = slots.raw.lock
    assert lock.acquire(False)  # the host is in the middle of a write
    try:
        assert posted(slots) == []  # did not wait: nothing this block
    finally:
        lock.release()
    assert posted(slots) == [(1, 1.0, 2.0, None, None)]


def test_with_a_lock_the_engine_drops_an_anchor_while_the_host_reads() -> None:
    shared = SharedClock(RATE, locked=True)
    shared.publish(10, 5.0, 0.01)
    lock = shared.raw.lock
    assert lock.acquire(False)  # the host is reading
    try:
        shared.publish(20, 6.0, 0.01)  # returns at once
    finally:
        lock.release()
    assert shared.dropped_anchors == 1
    assert shared.anchor() == (10, 5.0, 0.01)  # the last good anchor
    shared.publish(30, 7.0, 0.02)  # the next block
    assert shared.anchor() == (30, 7.0, 0.02)


@pytest.mark.parametrize(
    ("machine", "safe"),
    [
        ("x86_64", True),
        ("AMD64", True),
        ("i686", True),
        ("aarch64", False),
        ("arm64", False),
        ("armv7l", False),
        ("riscv64", False),
        ("ppc64le", False),
    ],
)
def test_sequence_locks_only_where_stores_stay_in_order(machine: str, safe: bool) -> None:
    assert sequence_locks_are_safe(machine) is safe


def test_the_platform_and_the_environment_choose_the_guard(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv(LOCKS_VARIABLE, raising=False)
    monkeypatch.setattr(shared_module.platform, "machine", lambda: "x86_64")
    assert not SharedClock(RATE).locked and not MoveSlots(1, CHANNELS).locked
    monkeypatch.setattr(shared_module.platform, "machine", lambda: "aarch64")
    assert SharedClock(RATE).locked and MoveSlots(1, CHANNELS).locked
    monkeypatch.setattr(shared_module.platform, "machine", lambda: "x86_64")
    monkeypatch.setenv(LOCKS_VARIABLE, "1")
    assert SharedClock(RATE).locked and MoveSlots(1, CHANNELS).locked
    # the engine process takes the guard the host chose, whatever its own environment
    assert SharedClock(RATE, SharedBuffer.allocate(4, locked=False)).locked is False


def engine_side(clock_raw: SharedBuffer, slots_raw: SharedBuffer, count: int, ready: Any) -> None:
    """Another process, as the engine: publish anchors and (standing in for the host)
    write moves, as fast as it can."""
    clock = SharedClock(RATE, clock_raw)
    slots = MoveSlots(1, CHANNELS, slots_raw)
    ready.set()
    for k in range(1, count + 1):
        clock.publish(k, k * 0.5, k * 0.25)
        slots.write(0, 1, gains(float(k), 2.0 * k), None, None)


def test_another_process_is_never_seen_half_written(locked: bool) -> None:
    clock = SharedClock(RATE, locked=locked)
    slots = MoveSlots(1, CHANNELS, locked=locked)
    slots.bind(0, 1, 1)
    count = 100_000
    context = multiprocessing.get_context("spawn")
    ready = context.Event()
    process: Any = context.Process(target=engine_side, args=(clock.raw, slots.raw, count, ready))
    process.start()
    moves: list[tuple[float, float]] = []
    anchors: set[int] = set()
    try:
        assert ready.wait(timeout=60)
        while process.is_alive():
            frame, anchor_s, latency_s = clock.anchor()
            assert (anchor_s, latency_s) == (frame * 0.5, frame * 0.25)
            anchors.add(frame)
            slots.drain(lambda contact, g, intensity, at: moves.append((float(g[0]), float(g[1]))))
    finally:
        process.join(timeout=60)
    assert process.exitcode == 0
    slots.drain(lambda contact, g, intensity, at: moves.append((float(g[0]), float(g[1]))))
    # read while the other process wrote, never a mix of two writes
    assert len(anchors) > 1 and len(moves) > 1
    assert all(y == 2.0 * x for x, y in moves)
    assert moves[-1] == (float(count), 2.0 * count)  # the newest position arrives
    # with a lock, the engine may have dropped its last anchors while this process read
    assert clock.anchor()[0] == count if not locked else 0 < clock.anchor()[0] <= count


def test_slots_run_out_and_come_back() -> None:
    slots = MoveSlots(2, CHANNELS)
    first, second = slots.allocate(), slots.allocate()
    assert first is not None and second is not None and slots.allocate() is None
    slots.release(first[0])
    assert slots.allocate() == (first[0], pytest.approx(3))


def test_blocks_the_inbox_thread_retires_while_the_callback_collects_are_all_unmapped() -> None:
    """The inbox thread maps (retiring the block a key had) while the callback collects,
    switching threads as often as the interpreter can: every retired block is unmapped."""
    host = [write_block([np.zeros(4)])[0] for _ in range(4)]
    maps = 20000
    blocks: MappedBlocks[int] = MappedBlocks()
    freed: list[int] = []
    done = threading.Event()
    errors: list[BaseException] = []
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:

        def inbox() -> None:
            try:
                for i in range(maps):
                    blocks.map(i % 2, host[i % 4].name)  # each map retires the block it replaces
            except BaseException as exc:  # the test fails on it, not waits for it forever
                errors.append(exc)
            finally:
                done.set()

        thread = threading.Thread(target=inbox)
        thread.start()
        while not done.is_set():
            freed.extend(blocks.collect())
        thread.join()
        freed.extend(blocks.collect())
    finally:
        sys.setswitchinterval(interval)
        for block in host:
            unlink_block(block)
    assert not errors, f"the inbox thread failed: {errors[0]!r}"
    assert len(freed) == maps - 2


def test_the_figures_never_set_the_heartbeat_back() -> None:
    """The figures are written on another thread than the heartbeat: a frame count they
    read a moment before the callback's next beat is not written over it."""
    status = StatusBlock(CHANNELS)
    status.beat(12.5, 4096)
    levels = [0.5] * CHANNELS
    status.write({"now_frames": 3968, "beat_s": 1.0, "active_voices": 3, "levels": levels})
    figures = status.read()
    assert (figures["beat_s"], figures["now_frames"]) == (12.5, 4096)
    assert figures["active_voices"] == 3 and figures["levels"] == levels
