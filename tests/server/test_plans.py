"""The plan cache: same pattern, same plan; bounded; big patterns are not kept."""

from __future__ import annotations

from phantomtouch import DeviceProfile, TouchPattern, preset
from phantomtouch.renderer import plan
from phantomtouch.server.plans import PlanCache


def test_same_pattern_same_plan() -> None:
    cache = PlanCache(DeviceProfile.default())
    first = cache.plan(preset("vr/tap"))
    assert cache.plan(preset("vr/tap")) is first
    assert first.summary() == plan(preset("vr/tap")).summary()
    assert cache.plan(preset("vr/stroke")) is not first


def test_bounded_least_recently_used() -> None:
    cache = PlanCache(DeviceProfile.default(), capacity=2)
    tap = cache.plan(preset("vr/tap"))
    cache.plan(preset("vr/stroke"))
    cache.plan(preset("vr/tap"))
    cache.plan(preset("vr/caress"))
    assert len(cache) == 2
    assert cache.plan(preset("vr/tap")) is tap, "the most recently used stays"


def test_big_patterns_are_not_kept() -> None:
    cache = PlanCache(DeviceProfile.default())
    points = [[1.9, 2.0 + k * 0.001] for k in range(2000)]
    big = TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": points}, "speed_cm_s": 5}
    )
    assert cache.plan(big).path_length_cm > 0
    assert len(cache) == 0
