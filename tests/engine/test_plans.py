"""The one plan cache: same pattern, same plan; bounded in bytes; big patterns are not
kept; the audio side holds a plan by its handle from its hand-over to its release."""

from __future__ import annotations

import gc
import tracemalloc
from typing import Any

import pytest

from phantomtouch import DeviceProfile, TouchPattern, preset
from phantomtouch.engine import Engine
from phantomtouch.engine.messages import DropPlan, HoldPlan, StartJob
from phantomtouch.engine.plans import PlanCache, plan_bytes
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.output.sinks import CaptureSink, NullSink
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.renderer import plan
from tests.support.waiting import wait_until


def line(points: int, offset_cm: float) -> TouchPattern:
    """A still-valid polyline of ``points`` points, distinct for each ``offset_cm``."""
    points_cm = [[1.9, 2.0 + offset_cm + k * 1e-5] for k in range(points)]
    return TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": points_cm}, "speed_cm_s": 5}
    )


def test_same_pattern_same_plan() -> None:
    cache = PlanCache(DeviceProfile.default())
    first = cache.plan(preset("vr/tap"))
    assert cache.plan(preset("vr/tap")) is first
    assert first.summary() == plan(preset("vr/tap")).summary()
    assert cache.plan(preset("vr/stroke")) is not first


def test_bounded_least_recently_used() -> None:
    cache = PlanCache(DeviceProfile.default(), max_bytes=1 << 20)
    tap = cache.plan(preset("vr/tap"))
    for k in range(200):  # ~50 KB each: the bound is reached many times over
        cache.plan(line(500, k * 1e-3))
        assert cache.plan(preset("vr/tap")) is tap, "the most recently used stays"
    assert cache.bytes <= cache.max_bytes
    assert 10 < len(cache) < 200


def test_big_patterns_are_not_kept() -> None:
    cache = PlanCache(DeviceProfile.default(), max_bytes=1 << 20)
    big = line(2000, 0.0)
    assert cache.plan(big).path_length_cm > 0
    assert len(cache) == 0 and cache.bytes == 0


def test_the_bound_holds_in_real_memory() -> None:
    """What tracemalloc sees the kept plans hold stays within the cache's bound.

    Each pattern is built, planned, and dropped by the test: whatever stays allocated is
    held by the cache.
    """
    max_bytes = 4 << 20
    cache = PlanCache(DeviceProfile.default(), max_bytes=max_bytes)
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for k in range(120):
            cache.plan(line(1000, k * 1e-3))
        gc.collect()
        held = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(cache) < 120, "the bound was reached"
    assert held <= max_bytes, f"{held} bytes held for a bound of {max_bytes}"
    assert held >= max_bytes / 4, "the estimate is not wildly above what plans hold"


def spy_on_posts(engine: Any, monkeypatch: pytest.MonkeyPatch) -> list[object]:
    """Every message the front posts to its audio side, in order (the real side still
    performs or ships each one)."""
    posted: list[object] = []
    post = engine._audio.post

    def spy(message: object) -> None:
        posted.append(message)
        post(message)

    monkeypatch.setattr(engine._audio, "post", spy)
    return posted


def test_one_cache_by_content_one_handle_handed_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan the service makes, the same pattern built again, and the plan itself all
    reach the audio side as one handle, handed over once."""
    device = DeviceProfile.default()
    with Engine(device, CaptureSink(device), prerender_max_s=0.0) as engine:
        posted = spy_on_posts(engine, monkeypatch)
        planned = engine.plans.plan(preset("vr/stroke"))  # what a /touch request plans
        twin = TouchPattern.model_validate_json(preset("vr/stroke").model_dump_json())
        for pattern in (planned, twin, planned, preset("vr/stroke")):
            engine.schedule(pattern)
        held = [m for m in posted if isinstance(m, HoldPlan)]
        starts = [m for m in posted if isinstance(m, StartJob)]
        assert len(held) == 1 and held[0].plan is planned
        assert {m.plan_key for m in starts} == {held[0].handle}
        assert len(engine.plans) == 1


@pytest.mark.parametrize("local", [True, False], ids=["in-process", "engine-process"])
def test_the_audio_side_holds_what_it_was_handed_until_released(
    local: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A cache bound of about eight plans: twelve patterns drop the oldest; the audio
    side is told (``DropPlan``) and acknowledges (``PlanReleased``); the jobs of dropped
    plans still play to their end, and nothing is refused."""
    device = DeviceProfile.default()
    patterns = [line(40, k / 64) for k in range(12)]
    one = plan_bytes(plan(patterns[0], device), len(patterns[0].model_dump_json()))
    engine: Any = (
        Engine(device, NullSink(device), prerender_max_s=0.0, voice_cost=1e-4)
        if local
        else ProcessEngine(device, SinkSpec("null"), prerender_max_s=0.0, voice_cost=1e-4)
    )
    with engine:
        engine.plans.max_bytes = 17 * one // 2
        posted = spy_on_posts(engine, monkeypatch)
        jobs = [engine.schedule(pattern) for pattern in patterns]
        drops = [m.handle for m in posted if isinstance(m, DropPlan)]
        held = [m.handle for m in posted if isinstance(m, HoldPlan)]
        assert len(held) == 12, "each pattern handed over once"
        assert len(drops) >= 3 and drops == held[: len(drops)], "the oldest dropped"
        assert len(drops) + len(engine.plans) == 12, "what is not dropped is kept"
        wait_until(lambda: not engine.plans.releasing)  # every drop acknowledged
        wait_until(lambda: all(engine.job_state(j.job_id).state == "finished" for j in jobs), 30.0)
        assert engine.status().refused_commands == 0


def test_ready_only_once_the_samples_are_rendered_whole() -> None:
    cache = PlanCache(DeviceProfile.default())
    tap = preset("vr/tap")
    assert cache.ready(tap) is None, "nothing held yet"
    planned = cache.plan(tap)
    assert cache.ready(tap) is None, "planned, but scheduling it would still render it"
    held = cache.entry(tap)
    assert held.prerendered is not None and cache.ready(tap) is planned
    assert cache.ready(preset("vr/stroke")) is None, "another pattern is not held"


def test_a_plan_too_long_to_render_whole_is_never_ready() -> None:
    cache = PlanCache(DeviceProfile.default(), prerender_max_s=0.1)
    tap = preset("vr/tap")  # 0.15 s
    assert cache.entry(tap).prerendered is None
    assert cache.ready(tap) is None
