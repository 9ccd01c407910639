"""The pipes between the host and the engine process (phantomtouch/engine/link.py): the
report box's thread sends what the callback queued, oldest first, in a form the host's
``Connection.recv`` reads; past its bound new reports are dropped and counted."""

from __future__ import annotations

import multiprocessing
import threading
from typing import Any

from phantomtouch.engine.link import REPORTS_WAITING, ReportBox
from phantomtouch.engine.messages import Ended, PlanReleased, Started


def test_the_host_receives_the_reports_in_order_as_sent() -> None:
    host_end, engine_end = multiprocessing.Pipe(duplex=False)
    box = ReportBox(engine_end)
    blocks = [[Started("job", k, 128 * k, False), Ended("job", k - 1, 128 * k)] for k in range(50)]
    blocks.append([PlanReleased(7)])
    for events in blocks:
        box.put(events)
        box.wake()
    received = []
    for _ in blocks:
        assert host_end.poll(10.0), f"only {len(received)} of {len(blocks)} reports came"
        received.append(host_end.recv())
    assert received == blocks and box.dropped == 0
    host_end.close()


def test_beyond_its_bound_the_box_drops_new_reports_and_counts_them() -> None:
    host_end, engine_end = multiprocessing.Pipe(duplex=False)
    box = ReportBox(engine_end)  # never woken: everything waits
    for k in range(REPORTS_WAITING + 5):
        box.put([Ended("job", k, k)])
    assert box.dropped == 5
    box.wake()
    first = host_end.recv() if host_end.poll(10.0) else None
    assert first == [Ended("job", 0, 0)]
    host_end.close()


def test_woken_the_box_does_its_chores_and_sends_what_they_return() -> None:
    host_end, engine_end = multiprocessing.Pipe(duplex=False)
    box = ReportBox(engine_end)
    done = threading.Semaphore(0)
    freed = iter([[], [PlanReleased(3)]])

    def chores() -> list[Any]:
        done.release()
        return next(freed)

    box.chores = chores
    box.wake()  # nothing waits: the thread still wakes for its chores, which free nothing
    assert done.acquire(timeout=10.0)
    assert not host_end.poll(0.5)
    box.put([Started("job", 1, 128, False)])
    box.wake()
    assert done.acquire(timeout=10.0)
    received = [host_end.recv() for _ in range(2) if host_end.poll(10.0)]
    assert received == [[Started("job", 1, 128, False)], [PlanReleased(3)]]
    host_end.close()
