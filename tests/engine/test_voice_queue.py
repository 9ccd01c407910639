"""The bounded command queue: refusals, never-refused releases, the stop-all mark."""

from __future__ import annotations

import threading

import pytest

from phantomtouch import DeviceProfile, EngineBusyError, TouchPattern
from phantomtouch.engine.voice_queue import CommandQueue, ReleaseCommand, StartCommand
from phantomtouch.engine.voices import PatternVoice
from phantomtouch.renderer import plan

PLAN = plan(
    TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[1, 1]]}, "duration_s": 2.0}
    ),
    DeviceProfile.default(),
)


def voice() -> PatternVoice:
    return PatternVoice(PLAN, job=1, release_frames=10)


def test_a_full_queue_raises_engine_busy_and_never_drops_silently() -> None:
    queue = CommandQueue(3)
    voices = [voice() for _ in range(3)]
    for v in voices:
        queue.push_start(v, 0, asap=False)
    with pytest.raises(EngineBusyError, match=r"full \(3 voices waiting"):
        queue.push_start(voice(), 0, asap=False)
    assert queue.depth == 3
    popped = [queue.pop() for _ in range(3)]
    assert [c.voice for c in popped if isinstance(c, StartCommand)] == voices
    assert queue.pop() is None
    queue.retire()
    assert queue.depth == 2
    queue.push_start(voice(), 0, asap=False)  # room for one again


def test_releases_are_never_refused_and_keep_their_order() -> None:
    queue = CommandQueue(1)
    queue.push_start(voice(), 0, asap=True)
    released = [voice() for _ in range(5)]
    for v in released:
        queue.push_release(v, None)
    commands = [queue.pop() for _ in range(6)]
    assert isinstance(commands[0], StartCommand)
    assert [c.voice for c in commands[1:] if isinstance(c, ReleaseCommand)] == released
    assert [c.seq for c in commands if c is not None] == sorted(c.seq for c in commands if c)


def test_stop_all_marks_everything_before_it_and_frees_the_capacity() -> None:
    queue = CommandQueue(2)
    first = queue.push_start(voice(), 0, asap=False)
    queue.push_start(voice(), 0, asap=False)
    mark = queue.mark_stop_all()
    assert mark > first.seq and queue.stop_all_seq == mark
    assert queue.depth == 0  # what waited will never start
    later = queue.push_start(voice(), 0, asap=False)
    assert later.seq > mark and later.voice.seq == later.seq


def test_concurrent_producers_never_exceed_the_capacity() -> None:
    queue = CommandQueue(100)
    accepted, refused = [], []

    def produce() -> None:
        for _ in range(60):
            try:
                accepted.append(queue.push_start(voice(), 0, asap=True))
            except EngineBusyError:
                refused.append(1)

    threads = [threading.Thread(target=produce) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(accepted) == 100 and len(refused) == 140
    assert len({c.seq for c in accepted}) == 100
