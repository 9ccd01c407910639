"""Planning: eq. 1 durations, duration_s semantics, strokes, layout fit, plan-time checks."""

from __future__ import annotations

import json

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.errors import ParameterError
from phantomtouch.schema import DeviceProfile, TouchPattern, limits


def pattern(**fields) -> TouchPattern:
    data = {"path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]}}
    data.update(fields)
    if (
        "speed_cm_s" not in data
        and "duration_s" not in data
        and data["path"]["kind"] != "keyframes"
    ):
        data["speed_cm_s"] = 5.0
    return TouchPattern.model_validate(data)


# --- eq. 1: T = T_fade_in + d / v + T_fade_out -----------------------------------------


@pytest.mark.parametrize(
    "speed, paper_s",
    [
        (3, 12.0),  # paper, sec. VI: "12s"
        (18, 4.0),  # paper, sec. VI: "4s"
        # The paper quotes 5.14 s for 10 cm/s, but its own rule (up and down the 14.4 cm
        # band, each direction with 0.6 s fades) gives 2 * (0.6 + 1.44 + 0.6) = 5.28 s.
        # The 12 s and 4 s above fix the rule, so 5.14 s must be a slip in the paper.
        (10, 5.28),
    ],
)
def test_exp1_durations_follow_eq_1(speed, paper_s):
    for signal in ("sine100", "noise", "combined50"):
        for suffix in ("", "-am"):
            resolved = pt.plan(pt.preset(f"exp1/{signal}-low-v{speed}{suffix}"))
            # Sums of a few floats: the durations agree to rounding.
            assert resolved.duration_s == pytest.approx(paper_s, rel=1e-12)
            assert resolved.strokes == 2
            assert resolved.stroke_s == pytest.approx(0.6 + 14.4 / speed + 0.6, rel=1e-12)
            assert resolved.frames == round(paper_s * 48000)


def test_custom_pattern_duration_is_fade_in_plus_length_over_speed_plus_fade_out(rng):
    for _ in range(50):
        points = rng.uniform((0, 0), (3.8, 14.4), size=(rng.integers(2, 6), 2))
        length = float(np.sum(np.hypot(*np.diff(points, axis=0).T)))
        speed = float(rng.uniform(0.5, 30))
        fade_in, fade_out = (float(f) for f in rng.uniform(0, 1, size=2))
        resolved = pt.plan(
            pattern(
                path={"kind": "polyline", "points_cm": points.tolist()},
                speed_cm_s=speed,
                fade_in_s=fade_in,
                fade_out_s=fade_out,
            )
        )
        # Lengths and times are a few float64 sums and quotients: equal to rounding.
        assert resolved.path_length_cm == pytest.approx(length, rel=1e-12)
        assert resolved.speed_cm_s == speed
        assert resolved.motion_s == pytest.approx(length / speed, rel=1e-12)
        assert resolved.duration_s == pytest.approx(fade_in + length / speed + fade_out, rel=1e-12)
        assert resolved.frames == round(resolved.duration_s * 48000)


def test_duration_s_is_the_whole_pattern_with_every_stroke_and_fade():
    resolved = pt.plan(pattern(duration_s=9.0, repeat=3, fade_in_s=0.5, fade_out_s=0.25))
    assert resolved.duration_s == pytest.approx(9.0)
    assert resolved.stroke_s == pytest.approx(3.0)
    assert resolved.motion_s == pytest.approx(3.0 - 0.75)
    assert resolved.speed_cm_s == pytest.approx(9.6 / 2.25)


def test_repeat_multiplies_the_stroke_and_each_stroke_has_its_own_fades():
    one = pt.plan(pattern(speed_cm_s=4.8))
    three = pt.plan(pattern(speed_cm_s=4.8, repeat=3, alternate=True))
    assert three.stroke_s == pytest.approx(one.stroke_s)
    assert three.duration_s == pytest.approx(3 * (0.6 + 2.0 + 0.6))
    assert three.backward is not None and one.backward is None


def test_keyframes_set_the_motion_time_and_the_mean_speed():
    resolved = pt.plan(
        pattern(
            path={
                "kind": "keyframes",
                "keyframes": [
                    {"t_s": 0.0, "x_cm": 0.0, "y_cm": 0.0},
                    {"t_s": 1.0, "x_cm": 0.0, "y_cm": 4.0},
                    {"t_s": 3.0, "x_cm": 0.0, "y_cm": 4.0},  # a two-second stop
                    {"t_s": 4.0, "x_cm": 3.0, "y_cm": 8.0},
                ],
            }
        )
    )
    assert resolved.motion_s == 4.0
    assert resolved.path_length_cm == pytest.approx(9.0)
    assert resolved.speed_cm_s == pytest.approx(9.0 / 4.0)
    assert resolved.duration_s == pytest.approx(5.2)


def test_still_touch_lasts_its_fades_or_its_duration():
    still = {"kind": "polyline", "points_cm": [[1.0, 1.0]]}
    assert pt.plan(pattern(path=still, speed_cm_s=3.0)).duration_s == pytest.approx(1.2)
    resolved = pt.plan(pattern(path=still, duration_s=2.0))
    assert resolved.duration_s == pytest.approx(2.0)
    assert resolved.speed_cm_s == 0.0


def test_summary_is_json_ready_and_complete():
    summary = pt.plan(pt.preset("exp2/curved")).summary()
    text = json.dumps(summary)
    for key in ("duration_s", "path_length_cm", "speed_cm_s", "frames", "channels"):
        assert key in json.loads(text)


# --- plan-time refusals ----------------------------------------------------------------


def test_duration_that_leaves_no_time_to_move_is_refused():
    with pytest.raises(ParameterError, match=r"duration_s=1\.0 .* fade_in_s \+ fade_out_s"):
        pt.plan(pattern(duration_s=1.0, fade_in_s=0.6, fade_out_s=0.6))


def test_speed_that_makes_the_pattern_longer_than_the_cap_is_refused():
    # 9.6 cm at 0.001 cm/s: 9600 s, past the documented 7200 s cap.
    with pytest.raises(ParameterError, match=r"at most 7200 s.*speed_cm_s"):
        pt.plan(pattern(speed_cm_s=0.001))
    with pytest.raises(ParameterError, match=r"at most 7200 s"):
        pt.plan(pattern(speed_cm_s=0.01, repeat=1000))


def test_duration_that_needs_a_speed_above_the_maximum_is_refused():
    # 9.6 cm in 1.205 - 1.2 = 0.005 s: 1920 cm/s.
    with pytest.raises(ParameterError, match=r"duration_s=1\.205 needs .* at most 1000 cm/s"):
        pt.plan(pattern(duration_s=1.205))
    # 9.6 cm in 0.01 s: 960 cm/s, just allowed.
    assert pt.plan(pattern(duration_s=1.21)).speed_cm_s == pytest.approx(960.0)
    far = {"kind": "polyline", "points_cm": [[0, 0], [0, 900]]}
    with pytest.raises(ParameterError, match=r"duration_s=1\.5 needs"):
        pt.plan(pattern(path=far, duration_s=1.5))


def test_keyframes_faster_than_the_maximum_speed_are_refused():
    path = {
        "kind": "keyframes",
        "keyframes": [
            {"t_s": 0.0, "x_cm": 0, "y_cm": 0},
            {"t_s": 1.0, "x_cm": 0, "y_cm": 1},
            {"t_s": 1.001, "x_cm": 0, "y_cm": 11},  # 10 cm in 1 ms
        ],
    }
    with pytest.raises(
        ParameterError, match=r"path\.keyframes\[2\]\.t_s=1\.001: .* at most 1000 cm/s"
    ):
        pt.plan(pattern(path=path))


def test_zero_duration_is_refused():
    still = {"kind": "keyframes", "keyframes": [{"t_s": 0.0, "x_cm": 1, "y_cm": 1}]}
    with pytest.raises(ParameterError, match="zero duration"):
        pt.plan(pattern(path=still, fade_in_s=0.0, fade_out_s=0.0))


@pytest.mark.parametrize(
    "carrier, sample_rate_hz, field, nyquist",
    [
        ({"kind": "sine", "freq_hz": 24000}, 48000, "carrier.freq_hz=24000.0", "24000 Hz"),
        ({"kind": "sine", "freq_hz": 30000}, 48000, "carrier.freq_hz=30000.0", "24000 Hz"),
        ({"kind": "combined", "freq_hz": 5000}, 8000, "carrier.freq_hz=5000.0", "4000 Hz"),
        ({"kind": "sine", "freq_hz": 4000}, 8000, "carrier.freq_hz=4000.0", "4000 Hz"),
    ],
)
def test_frequency_at_or_above_nyquist_is_refused_at_plan_time(
    carrier, sample_rate_hz, field, nyquist
):
    touch = pattern(carrier=carrier)
    with pytest.raises(ParameterError) as info:
        pt.render(touch, sample_rate_hz=sample_rate_hz)
    message = str(info.value)
    assert field in message
    assert f"Nyquist frequency {nyquist}" in message
    # Just below Nyquist is allowed (a sine needs only f < fs / 2).
    below = {**carrier, "freq_hz": sample_rate_hz / 2 - 1}
    assert pt.plan(pattern(carrier=below), DeviceProfile(sample_rate_hz=sample_rate_hz)).frames


def test_noise_band_above_the_filter_limit_is_refused():
    touch = pattern(carrier={"kind": "noise", "low_hz": 100, "high_hz": 3700})
    with pytest.raises(ParameterError, match=r"carrier\.high_hz=3700\.0 must be <= 3600 Hz"):
        pt.plan(touch, DeviceProfile(sample_rate_hz=8000))


def test_sample_rate_out_of_range_is_refused_with_its_name():
    with pytest.raises(ParameterError, match=r"sample_rate_hz=100 must be within \[8000, 192000\]"):
        pt.render(pattern(), sample_rate_hz=100)


# --- points outside the layout ---------------------------------------------------------


def test_outside_points_are_projected_by_default_and_counted():
    path = {"kind": "polyline", "points_cm": [[1.0, -2.0], [1.0, 5.0], [6.8, 18.4], [2.0, 3.0]]}
    resolved = pt.plan(pattern(path=path))
    assert resolved.projected_points == 2
    # (6.8, 18.4) is 3.0 cm right of x = 3.8 and 4.0 cm above y = 14.4: 5 cm off the corner.
    assert resolved.max_projection_cm == pytest.approx(5.0, rel=1e-12)  # a 3-4-5 triangle
    assert pt.plan(pattern()).projected_points == 0


def test_outside_error_refuses_a_point_outside_the_hull():
    path = {"kind": "polyline", "points_cm": [[1.0, 1.0], [1.0, 15.4]]}
    with pytest.raises(ParameterError) as info:
        pt.plan(pattern(path=path, outside="error"))
    message = str(info.value)
    assert "path point 1 at (1, 15.4) cm lies 1 cm outside" in message
    assert "outside='error'" in message
    inside = {"kind": "polyline", "points_cm": [[0.0, 0.0], [3.8, 14.4]]}
    assert pt.plan(pattern(path=inside, outside="error")).projected_points == 0


def test_outside_in_1d_mode_counts_only_y_beyond_the_rows():
    path = {"kind": "polyline", "points_cm": [[10.0, 1.0], [10.0, 16.4]]}
    resolved = pt.plan(pattern(path=path, mode="1d"))
    # 1D uses only y: x = 10 is fine, y = 16.4 is 2 cm past the last row.
    assert resolved.projected_points == 1
    assert resolved.max_projection_cm == pytest.approx(2.0)


def test_limits_are_the_documented_ones():
    assert limits.MAX_SPEED_CM_S == 1000.0
    assert limits.MAX_DURATION_S == 7200.0
    assert limits.MAX_PATH_POINTS == 100_000
