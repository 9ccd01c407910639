"""The plan cache: same pattern, same plan; bounded in bytes; big patterns are not kept."""

from __future__ import annotations

import gc
import tracemalloc

from phantomtouch import DeviceProfile, TouchPattern, preset
from phantomtouch.renderer import plan
from phantomtouch.service.plans import PlanCache


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
