"""Touch requests: three shapes told apart by their keys, timing, overrides."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from phantomtouch.renderer import preset
from phantomtouch.service.models import (
    AnyTouch,
    NamedTouch,
    PatternTouch,
    PresetTouch,
    parse_touch_request,
)

STROKE = {"path": {"kind": "polyline", "points_cm": [[1.9, 12], [1.9, 2.4]]}, "speed_cm_s": 5}


def parse(body: str) -> AnyTouch:
    return parse_touch_request(body)


def test_three_shapes() -> None:
    assert isinstance(parse('{"preset": "vr/tap"}'), PresetTouch)
    assert isinstance(parse('{"stored": "my-stroke", "start_at_s": 12.5}'), NamedTouch)
    touch = parse('{"path": {"kind": "polyline", "points_cm": [[1, 2]]}, "duration_s": 1}')
    assert isinstance(touch, PatternTouch)
    assert touch.pattern().duration_s == 1.0


def test_pattern_drops_timing() -> None:
    touch = parse(
        '{"path": {"kind": "polyline", "points_cm": [[1, 2]]}, "duration_s": 1, "start_in_ms": 5}'
    )
    assert isinstance(touch, PatternTouch)
    assert touch.start_in_ms == 5.0
    assert "start_in_ms" not in touch.pattern().model_dump()


def test_strict_numbers() -> None:
    with pytest.raises(ValidationError) as info:
        parse('{"stored": "x", "start_in_ms": "5"}')
    assert info.value.errors()[0]["loc"] == ("named", "start_in_ms")


def test_not_both_starts() -> None:
    with pytest.raises(ValidationError, match="not both"):
        parse('{"stored": "x", "start_in_ms": 5, "start_at_s": 3}')


def test_pattern_names_are_a_safe_set() -> None:
    with pytest.raises(ValidationError, match="should match pattern"):
        parse('{"stored": "../etc/passwd"}')


def test_pattern_is_the_deprecated_name_of_stored() -> None:
    legacy = parse('{"pattern": "my-stroke", "start_at_s": 12.5}')
    assert legacy == NamedTouch(stored="my-stroke", start_at_s=12.5)
    with pytest.raises(ValidationError, match="pattern"):
        parse('{"stored": "my-stroke", "pattern": "other"}')
    with pytest.raises(ValidationError, match="should match pattern"):
        parse('{"pattern": "../etc/passwd"}')


def test_overrides_replace_exclusive_fields() -> None:
    base = preset("exp2/curved")
    assert base.duration_s is not None
    touch = parse('{"preset": "exp2/curved", "overrides": {"speed_cm_s": 3, "level_db": 120}}')
    assert isinstance(touch, PresetTouch)
    pattern = touch.apply(base)
    assert (pattern.speed_cm_s, pattern.duration_s, pattern.level_db) == (3.0, None, 120.0)
    assert pattern.path == base.path


def test_overrides_keep_field_limits() -> None:
    with pytest.raises(ValidationError) as info:
        parse('{"preset": "vr/tap", "overrides": {"speed_cm_s": -1}}')
    assert info.value.errors()[0]["loc"] == ("preset", "overrides", "speed_cm_s")


def test_not_an_object() -> None:
    with pytest.raises(ValidationError, match="expected an object"):
        parse("[1, 2]")
