"""Job ids drawn in batches from the system's random source: unrepeated, 32 hex digits,
and safe to draw from several threads at once."""

from __future__ import annotations

import re
import threading

import pytest

from phantomtouch.engine.job_ids import ID_BYTES, JobIds
from phantomtouch.errors import ParameterError


def test_ids_are_32_hex_digits_and_never_repeat_across_batches() -> None:
    ids = JobIds(batch_ids=4)  # 2,500 batches: every refill is crossed many times
    drawn = [ids.next() for _ in range(10_000)]
    assert all(re.fullmatch(r"[0-9a-f]{32}", job_id) for job_id in drawn)
    assert len(set(drawn)) == len(drawn)
    assert len(drawn[0]) == 2 * ID_BYTES


def test_threads_drawing_at_once_get_distinct_ids() -> None:
    ids = JobIds(batch_ids=3)
    drawn: list[list[str]] = [[] for _ in range(4)]
    start = threading.Barrier(len(drawn))

    def draw(into: list[str]) -> None:
        start.wait()
        into.extend(ids.next() for _ in range(2_000))

    threads = [threading.Thread(target=draw, args=(into,)) for into in drawn]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    every = [job_id for into in drawn for job_id in into]
    assert len(every) == 8_000 and len(set(every)) == 8_000


def test_a_batch_of_no_ids_is_refused() -> None:
    with pytest.raises(ParameterError, match="batch_ids=0 must be >= 1"):
        JobIds(batch_ids=0)
