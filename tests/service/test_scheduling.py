"""The touch path (phantomtouch/service/scheduling.py) as a source's handle takes it: a
repeated touch whose plan the engine holds rendered whole is scheduled on the event loop
with no worker thread, under the same quota and stop voiding as one planned in a worker;
anything that reads the library or must be planned still goes to a worker. Over a real
engine rendering into a capture sink."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from phantomtouch.engine import Engine
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile, TouchPattern
from phantomtouch.service.admission import Admission, Handle, policy_table
from phantomtouch.service.errors import NotFoundError, QuotaError
from phantomtouch.service.models import (
    AnyTouch,
    JobAccepted,
    NamedTouch,
    PresetTouch,
    touch_request_adapter,
)
from phantomtouch.service.scheduling import LOOP_PATH_POINTS, loop_pattern
from phantomtouch.service.store import PatternStore
from tests.support.service import make_settings

DEVICE = DeviceProfile.default()
TAP = PresetTouch(preset="vr/tap")


class CountingExecutor(ThreadPoolExecutor):
    """A thread pool that counts the work handed to it."""

    submitted = 0

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        self.submitted += 1
        return super().submit(fn, *args, **kwargs)


@pytest.fixture
def engine() -> Iterator[Engine]:
    with Engine(DEVICE, CaptureSink(DEVICE, realtime=True)) as engine:
        yield engine


@pytest.fixture
def store(tmp_path: Path) -> Iterator[PatternStore]:
    store = PatternStore.open(tmp_path / "patterns.db")
    yield store
    store.close()


def rest_handle(engine: Engine, store: PatternStore, tmp_path: Path, **settings: Any) -> Handle:
    table = policy_table(make_settings(tmp_path, **settings))
    return Admission(engine, table, store=store).open("rest", "127.0.0.1", principal="rest:h")


def play_all(handle: Handle, requests: list[AnyTouch]) -> tuple[list[JobAccepted], int]:
    """Play ``requests`` one after the other on an event loop; the answers and how many
    calls went to a worker thread."""

    async def run() -> tuple[list[JobAccepted], int]:
        executor = CountingExecutor(max_workers=2)
        asyncio.get_running_loop().set_default_executor(executor)
        answers = [await handle.play(request, arrival=handle.arrival()) for request in requests]
        return answers, executor.submitted

    return asyncio.run(run())


def test_a_repeated_tap_is_planned_once_in_a_worker_then_scheduled_on_the_loop(
    engine: Engine, store: PatternStore, tmp_path: Path
) -> None:
    handle = rest_handle(engine, store, tmp_path)
    answers, to_workers = play_all(handle, [TAP] * 5)
    assert to_workers == 1, "only the first tap is planned (and rendered) in a worker"
    assert len({answer.job_id for answer in answers}) == 5
    assert {answer.duration_s for answer in answers} == {0.15}
    assert all(engine.job_state(a.job_id) is not None for a in answers)


def test_the_loop_keeps_the_quota_and_names_its_limit(
    engine: Engine, store: PatternStore, tmp_path: Path
) -> None:
    handle = rest_handle(engine, store, tmp_path, max_voices_per_client=2)
    play_all(handle, [TAP, TAP])
    with pytest.raises(QuotaError, match="max_voices_per_client=2 is used up") as refused:
        play_all(handle, [TAP])
    assert refused.value.field == "voices"


def test_a_stop_voids_a_held_tap_that_arrived_before_it(
    engine: Engine, store: PatternStore, tmp_path: Path
) -> None:
    handle = rest_handle(engine, store, tmp_path)
    play_all(handle, [TAP])  # its plan is held from now on

    async def tap_sent_before_the_stop() -> str:
        arrival = handle.arrival()
        engine.stop_all()
        return (await handle.play(TAP, arrival=arrival)).job_id

    voided = asyncio.run(tap_sent_before_the_stop())
    assert engine.job_state(voided).state == "stopped"  # type: ignore[union-attr]
    heard, _ = play_all(handle, [TAP])
    assert engine.job_state(heard[0].job_id).state != "stopped"  # type: ignore[union-attr]


def test_a_stored_pattern_or_a_pattern_not_yet_rendered_goes_to_a_worker(
    engine: Engine, store: PatternStore, tmp_path: Path
) -> None:
    tap = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 7.2]]},
            "duration_s": 0.02,
            "fade_in_s": 0.005,
            "fade_out_s": 0.01,
        }
    )
    store.put("mine", tap, {"duration_s": 0.02})
    handle = rest_handle(engine, store, tmp_path)
    other = {**tap.model_dump(exclude_unset=True), "duration_s": 0.03}  # a plan of its own
    inline = touch_request_adapter.validate_python(other)
    _, to_workers = play_all(handle, [NamedTouch(stored="mine")] * 2 + [inline] * 3)
    assert to_workers == 2 + 1, "the library is read in a worker; the inline tap once"


def test_only_a_preset_or_a_short_inline_path_without_a_clip_is_resolved_on_the_loop() -> None:
    assert loop_pattern(TAP) is not None
    assert loop_pattern(NamedTouch(stored="mine")) is None
    points = [[1.9, 2.0 + 0.1 * k] for k in range(LOOP_PATH_POINTS + 1)]
    long = {"path": {"kind": "polyline", "points_cm": points}, "speed_cm_s": 5.0}
    assert loop_pattern(touch_request_adapter.validate_python(long)) is None
    short = {**long, "path": {"kind": "polyline", "points_cm": points[:LOOP_PATH_POINTS]}}
    assert loop_pattern(touch_request_adapter.validate_python(short)) is not None
    clip = {**short, "carrier": {"kind": "clip", "clip": "buzz"}}
    assert loop_pattern(touch_request_adapter.validate_python(clip)) is None
    with pytest.raises(NotFoundError, match="vr/nothing"):
        loop_pattern(PresetTouch(preset="vr/nothing"))
