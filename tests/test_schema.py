"""Bad input is refused at the schema, with a message naming the field, value and range."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

import phantomtouch as pt
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema import DeviceProfile, TouchPattern, describe_validation_error, limits
from phantomtouch.schema.validation import error_items

NAN, INF = math.nan, math.inf


def base() -> dict[str, Any]:
    return {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 5.0,
        "carrier": {"kind": "sine", "freq_hz": 100.0},
        "modulation": {"index": 0.5, "freq_hz": "stroke"},
    }


def set_field(data: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    """``data`` with the field at a dotted path (list indices as numbers) replaced."""
    keys = [int(k) if k.isdigit() else k for k in dotted.split(".")]
    node = data
    for key in keys[:-1]:
        node = node[key]
    node[keys[-1]] = value
    return data


def refusal(data: dict[str, Any], model: type = TouchPattern) -> str:
    with pytest.raises(ValidationError) as info:
        model.model_validate(data)
    return describe_validation_error(info.value)


# (dotted field, bad value, what the message must say about the allowed range)
BAD_FIELDS = [
    ("speed_cm_s", NAN, "finite"),
    ("speed_cm_s", INF, "finite"),
    ("speed_cm_s", -INF, "finite"),
    ("speed_cm_s", 0.0, "greater than 0"),
    ("speed_cm_s", -3.0, "greater than 0"),
    ("speed_cm_s", 1000.5, "less than or equal to 1000"),
    ("fade_in_s", NAN, "finite"),
    ("fade_in_s", -0.1, "greater than or equal to 0"),
    ("fade_out_s", 61.0, "less than or equal to 60"),
    ("repeat", 0, "greater than or equal to 1"),
    ("repeat", 1001, "less than or equal to 1000"),
    ("path.points_cm.0.0", NAN, "finite"),
    ("path.points_cm.1.1", INF, "finite"),
    ("path.points_cm.1.1", 1000.5, "less than or equal to 1000"),
    ("carrier.freq_hz", NAN, "finite"),
    ("carrier.freq_hz", 0.0, "greater than or equal to 20"),
    ("carrier.freq_hz", 0.01, "greater than or equal to 20"),
    ("carrier.freq_hz", 96000.0, "less than 96000"),
    ("modulation.index", -0.1, "greater than or equal to 0"),
    ("modulation.index", 1.01, "less than or equal to 1"),
    ("modulation.index", NAN, "less than or equal to 1"),  # NaN fails either bound
    ("modulation.freq_hz", 0.0, "must be > 0 and <= 1000 Hz"),
    ("modulation.freq_hz", NAN, "must be > 0 and <= 1000 Hz"),
    ("modulation.freq_hz", 1500.0, "must be > 0 and <= 1000 Hz"),
    ("level_db", 59.0, "greater than or equal to 60"),
    ("level_db", NAN, "finite"),
    ("level_db", 181.0, "less than or equal to 180"),
    ("law", "cubic", "'linear', 'log' or 'power'"),
    ("mode", "3d", "'1d' or '2d'"),
    ("outside", "clip", "'project' or 'error'"),
]


@pytest.mark.parametrize("field, value, allowed", BAD_FIELDS)
def test_bad_field_is_refused_with_field_value_and_range(field, value, allowed):
    data = set_field(base(), field, value)
    if field == "level_db":
        data.pop("modulation")
    message = refusal(data)
    leaf = field.split(".")[-1] if not field.split(".")[-1].isdigit() else "points_cm"
    assert leaf in message
    assert repr(value) in message or str(value) in message
    assert allowed in message


def test_intensity_outside_zero_to_one_or_the_presets_is_refused():
    for value in (-0.1, 1.5, NAN, "loud"):
        message = refusal({**base(), "intensity": value})
        assert "intensity" in message
        assert "'low' or 'high'" in message


def test_duration_over_the_cap_and_non_positive_are_refused():
    data = {**base(), "duration_s": 7200.5}
    data.pop("speed_cm_s")
    assert "duration_s=7200.5: Input should be less than or equal to 7200" in refusal(data)
    assert "duration_s=0.0: Input should be greater than 0" in refusal({**data, "duration_s": 0.0})


def test_speed_and_duration_together_are_refused():
    message = refusal({**base(), "duration_s": 3.0})
    assert "give exactly one of speed_cm_s or duration_s (got both: 5.0, 3.0)" in message


def test_neither_speed_nor_duration_is_refused():
    data = base()
    data.pop("speed_cm_s")
    assert "give exactly one of speed_cm_s or duration_s" in refusal(data)


def test_keyframes_take_neither_speed_nor_duration():
    data = {
        **base(),
        "path": {"kind": "keyframes", "keyframes": [{"t_s": 0, "x_cm": 0, "y_cm": 0}]},
    }
    assert "speed_cm_s does not apply to a keyframe path" in refusal(data)


def test_intensity_and_level_db_together_are_refused():
    assert "either intensity or level_db" in refusal({**base(), "intensity": 0.5, "level_db": 120})


@pytest.mark.parametrize("kind", ["polyline", "spline"])
def test_too_many_path_points_are_refused(kind):
    points = [[1.0, 1.0 + i * 1e-4] for i in range(limits.MAX_PATH_POINTS + 1)]
    message = refusal({**base(), "path": {"kind": kind, "points_cm": points}})
    assert "path.points_cm=" in message  # the field; the union's branch name is no field
    assert "at most 100000 items" in message and "not 100001" in message


def test_too_many_keyframes_are_refused():
    frames = [{"t_s": i * 0.01, "x_cm": 1, "y_cm": 1} for i in range(limits.MAX_PATH_POINTS + 1)]
    data = {**base(), "path": {"kind": "keyframes", "keyframes": frames}}
    data.pop("speed_cm_s")
    message = refusal(data)
    assert "path.keyframes=" in message and "keyframes.keyframes" not in message
    assert "at most 100000 items" in message


@pytest.mark.parametrize("times", [[0.0, 1.0, 1.0], [0.0, 2.0, 1.5]])
def test_keyframe_times_must_strictly_increase(times):
    frames = [{"t_s": t, "x_cm": 1.0, "y_cm": float(i)} for i, t in enumerate(times)]
    data = {**base(), "path": {"kind": "keyframes", "keyframes": frames}}
    data.pop("speed_cm_s")
    message = refusal(data)
    assert f"keyframes[2].t_s={times[2]!r} must be greater than keyframes[1].t_s={times[1]!r}" in (
        message
    )


def test_keyframe_intensity_and_time_ranges():
    frames = [{"t_s": -1.0, "x_cm": 1.0, "y_cm": 1.0, "intensity": 2.0}]
    data = {**base(), "path": {"kind": "keyframes", "keyframes": frames}}
    data.pop("speed_cm_s")
    message = refusal(data)
    assert "keyframes[0].t_s=-1.0: Input should be greater than or equal to 0" in message
    assert "keyframes[0].intensity=2.0: Input should be less than or equal to 1" in message


def test_noise_band_must_be_ordered():
    message = refusal({**base(), "carrier": {"kind": "noise", "low_hz": 500, "high_hz": 400}})
    assert "high_hz=400.0 must be at least 5 % above low_hz=500.0" in message


def test_unknown_fields_are_refused_by_name():
    message = refusal({**base(), "speed": 5.0})
    assert "speed=5.0: Extra inputs are not permitted" in message


def test_error_items_give_field_value_and_message_separately():
    with pytest.raises(ValidationError) as info:
        TouchPattern.model_validate({**base(), "speed_cm_s": -1.0})
    (item,) = error_items(info.value)
    assert item == {
        "field": "speed_cm_s",
        "value": -1.0,
        "message": "Input should be greater than 0",
    }


def test_json_with_nan_is_refused():
    text = json.dumps({**base(), "speed_cm_s": NAN})  # Python writes NaN, not valid JSON
    with pytest.raises(ValidationError) as info:
        TouchPattern.model_validate_json(text)
    assert "speed_cm_s" in describe_validation_error(info.value)


# --- random invalid input ------------------------------------------------------------------

_NON_FINITE = st.sampled_from([NAN, INF, -INF])
INVALID = st.one_of(
    st.tuples(
        st.just("speed_cm_s"),
        st.one_of(
            _NON_FINITE, st.floats(max_value=0.0), st.floats(min_value=1000.0, exclude_min=True)
        ),
    ),
    st.tuples(
        st.just("fade_in_s"),
        st.one_of(
            _NON_FINITE,
            st.floats(max_value=0.0, exclude_max=True),
            st.floats(min_value=60.0, exclude_min=True),
        ),
    ),
    st.tuples(st.just("repeat"), st.one_of(st.integers(max_value=0), st.integers(min_value=1001))),
    st.tuples(
        st.just("path.points_cm.0.1"),
        st.one_of(_NON_FINITE, st.floats(min_value=1000.0, exclude_min=True)),
    ),
    st.tuples(
        st.just("carrier.freq_hz"),
        st.one_of(
            _NON_FINITE,
            st.floats(max_value=20.0, exclude_max=True),  # below the actuators' band
            st.floats(min_value=96000.0),
        ),
    ),
    st.tuples(
        st.just("modulation.index"),
        st.one_of(
            _NON_FINITE,
            st.floats(max_value=0.0, exclude_max=True),
            st.floats(min_value=1.0, exclude_min=True),
        ),
    ),
    st.tuples(
        st.just("intensity"),
        st.one_of(
            _NON_FINITE,
            st.floats(max_value=0.0, exclude_max=True),
            st.floats(min_value=1.0, exclude_min=True),
            st.text(max_size=5),
        ),
    ),
    st.tuples(
        st.just("law"), st.text(max_size=8).filter(lambda s: s not in ("linear", "log", "power"))
    ),
)


@given(invalid=INVALID)
def test_random_invalid_inputs_are_refused_naming_the_field(invalid):
    field, value = invalid
    data = set_field(base(), field, value)
    try:
        pt.plan(TouchPattern.model_validate(data))
    except ValidationError as exc:
        message = describe_validation_error(exc)
    except ParameterError as exc:  # pragma: no cover - every case above is a schema error
        message = str(exc)
    else:
        raise AssertionError(f"{field}={value!r} was accepted")
    leaf = [part for part in field.split(".") if not part.isdigit()][-1]
    assert leaf in message
    assert "\n" not in message


@given(freq_hz=st.floats(24000.0, 95999.0))
def test_random_frequencies_at_or_above_nyquist_are_refused_at_plan_time(freq_hz):
    data = set_field(base(), "carrier.freq_hz", freq_hz)
    with pytest.raises(ParameterError) as info:
        pt.plan(TouchPattern.model_validate(data))
    assert f"carrier.freq_hz={freq_hz!r}" in str(info.value)
    assert "Nyquist frequency 24000 Hz" in str(info.value)


# --- device profiles ------------------------------------------------------------------------


def actuators(points: list[tuple[float, float]]) -> list[dict[str, Any]]:
    return [{"x_cm": x, "y_cm": y, "channel": i + 1} for i, (x, y) in enumerate(points)]


DUPLICATE = [(0.0, 0.0), (3.8, 0.0), (0.0, 4.8), (3.8, 0.0)]
COLLINEAR = [(0.0, 0.0), (1.0, 2.0), (2.0, 4.0), (3.0, 6.0)]


def write_toml(path, points) -> None:
    lines = ['name = "test"']
    for a in actuators(points):
        lines += [
            "[[actuators]]",
            f"x_cm = {a['x_cm']}",
            f"y_cm = {a['y_cm']}",
            f"channel = {a['channel']}",
        ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_json(path, points) -> None:
    path.write_text(json.dumps({"name": "test", "actuators": actuators(points)}), encoding="utf-8")


@pytest.mark.parametrize("write", [write_toml, write_json], ids=["toml", "json"])
def test_duplicate_actuators_are_refused_when_loaded(tmp_path, write):
    path = tmp_path / ("device.toml" if write is write_toml else "device.json")
    write(path, DUPLICATE)
    with pytest.raises(DeviceError) as info:
        DeviceProfile.load(path)
    message = str(info.value)
    assert str(path) in message
    assert "actuators[1] at (3.8, 0) cm and actuators[3] at (3.8, 0) cm are 0 cm apart" in message
    assert "at least 0.1 cm" in message


@pytest.mark.parametrize("write", [write_toml, write_json], ids=["toml", "json"])
def test_collinear_actuators_are_refused_when_loaded(tmp_path, write):
    path = tmp_path / ("device.toml" if write is write_toml else "device.json")
    write(path, COLLINEAR)
    with pytest.raises(DeviceError) as info:
        DeviceProfile.load(path)
    message = str(info.value)
    assert "actuators at (0, 0), (1, 2), (2, 4), (3, 6) cm are collinear" in message


def test_degenerate_layouts_are_refused_by_model_validate():
    for points, expected in ((DUPLICATE, "0 cm apart"), (COLLINEAR, "collinear")):
        with pytest.raises(ValidationError, match=expected):
            DeviceProfile.model_validate({"actuators": actuators(points)})


def test_a_valid_custom_layout_loads(tmp_path):
    path = tmp_path / "device.toml"
    write_toml(path, [(0.0, 0.0), (4.0, 0.0), (0.0, 5.0), (4.0, 5.0), (2.0, 8.0)])
    device = DeviceProfile.load(path)
    assert device.channels == 5 and device.triangles is None
    assert pt.gains_at(device, 2.0, 8.0)[4] == 1.0


def test_unreadable_or_unparsable_profiles_are_device_errors(tmp_path):
    with pytest.raises(DeviceError, match="cannot read device profile"):
        DeviceProfile.load(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("actuators = [", encoding="utf-8")
    with pytest.raises(DeviceError, match="cannot read device profile"):
        DeviceProfile.load(broken)


@pytest.mark.parametrize(
    "update, expected",
    [
        (
            {"actuators": [*actuators([(0, 0), (1, 0)]), {"x_cm": 0, "y_cm": 1, "channel": 1}]},
            "channels [1, 2, 1] must be distinct",
        ),
        (
            {"actuators": actuators([(0, 0), (1, 0), (0, 1)]), "triangles": [[0, 1, 3]]},
            "triangles[0]=(0, 1, 3) must name 3 distinct actuators in [0, 2]",
        ),
        (
            {"calibration": {"channel_level_db": [150.0] * 7}},
            "calibration.channel_level_db has 7 entries; the profile has 8 channels",
        ),
        (
            {"calibration": {"reference_level_db": 140.0}},
            "safety.max_level_db=150.0 must not exceed calibration.reference_level_db=140.0",
        ),
        (
            {"safety": {"ceiling": 1.5}},
            "safety.ceiling=1.5: Input should be less than or equal to 1",
        ),
        (
            {"gain_update_frames": 0},
            "gain_update_frames=0: Input should be greater than or equal to 1",
        ),
        (
            {"gain_update_s": 0.0},
            "gain_update_s=0.0: Input should be greater than 0",
        ),
        (
            {"gain_update_s": 0.5},
            "gain_update_s=0.5: Input should be less than or equal to 0.02",
        ),
        (
            {"sample_rate_hz": 1000},
            "sample_rate_hz=1000: Input should be greater than or equal to 8000",
        ),
    ],
)
def test_device_profile_fields_are_validated_with_field_and_value(update, expected):
    assert expected in refusal(update, DeviceProfile)


@pytest.mark.parametrize(
    ("sample_rate_hz", "frames"), [(8000, 21), (44100, 118), (48000, 128), (192000, 512)]
)
def test_the_control_interval_is_a_time_rounded_to_frames(sample_rate_hz, frames):
    device = DeviceProfile(sample_rate_hz=sample_rate_hz)
    assert device.gain_step_frames == frames  # 2.667 ms at each rate
    assert DeviceProfile(sample_rate_hz=sample_rate_hz, gain_update_frames=7).gain_step_frames == 7
    assert DeviceProfile(sample_rate_hz=8000, gain_update_s=1e-5).gain_step_frames == 1


# --- the JSON Schema states the rules it can ---------------------------------------------

STILL = {"kind": "polyline", "points_cm": [[1.9, 7.2]]}
KEYFRAMES = {"kind": "keyframes", "keyframes": [{"t_s": 0.0, "x_cm": 1.9, "y_cm": 7.2}]}
SCHEMA_CASES = [
    # (body, accepted)
    ({"path": STILL, "duration_s": 1.0}, True),
    ({"path": STILL, "speed_cm_s": 5.0}, True),
    ({"path": STILL}, False),  # neither speed_cm_s nor duration_s
    ({"path": STILL, "speed_cm_s": 5.0, "duration_s": 1.0}, False),  # both
    ({"path": STILL, "speed_cm_s": None, "duration_s": 1.0}, True),  # null is absent
    ({"path": KEYFRAMES}, True),
    ({"path": KEYFRAMES, "speed_cm_s": 5.0}, False),  # keyframes carry their own times
    ({"path": STILL, "duration_s": 1.0, "intensity": "low", "level_db": 120.0}, False),
    ({"path": STILL, "duration_s": 1.0, "intensity": "low", "level_db": None}, True),
    ({"path": STILL, "duration_s": 1.0, "level_db": 120.0}, True),
    ({"path": STILL, "duration_s": 1.0, "modulation": {"freq_hz": 0.0}}, False),
    ({"path": STILL, "duration_s": 1.0, "modulation": {"freq_hz": 1000.0}}, True),
    ({"path": STILL, "duration_s": 1.0, "modulation": {"freq_hz": 1000.5}}, False),
    ({"path": STILL, "duration_s": 1.0, "modulation": {"freq_hz": "stroke"}}, True),
    ({"path": {"points_cm": [[1.9, 7.2]]}, "duration_s": 1.0}, False),  # kind is required
    ({"path": STILL, "duration_s": 1.0, "carrier": {"freq_hz": 100.0}}, False),
    ({"path": STILL, "duration_s": 1.0, "repeat": 2.0, "carrier": {"kind": "noise"}}, True),
]


@pytest.mark.parametrize(("body", "accepted"), SCHEMA_CASES)
def test_the_json_schema_and_the_model_agree(body, accepted):
    import jsonschema_rs  # schemathesis' validator, a dev dependency

    validator = jsonschema_rs.validator_for(TouchPattern.model_json_schema())
    assert validator.is_valid(body) is accepted
    # The model, validated from the JSON in strict mode as the server does.
    try:
        TouchPattern.__pydantic_validator__.validate_json(json.dumps(body), strict=True)
    except ValidationError:
        assert not accepted
    else:
        assert accepted
