"""Control rate: where the point is (eq. 1 timing) and how strong it is (fades, eq. 2)."""

from __future__ import annotations

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.renderer.trajectory import control_gains, envelope_at, positions_at
from phantomtouch.schema import TouchPattern

# Envelopes are a few products of float64 terms: exact to rounding.
EXACT = 1e-12
# Times folded into a stroke (t - k * stroke_s) or shifted by whole strokes lose a few
# ulps of a value of several seconds; eq. 2 and the fades are Lipschitz, so their values
# move by far less than this.
SHIFTED = 1e-9


def plan_of(**fields) -> pt.Plan:
    data = {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 4.8,  # 2 s of motion
    }
    data.update(fields)
    return pt.plan(TouchPattern.model_validate(data))


def eq2(m: float, cycles: np.ndarray) -> np.ndarray:
    """Eq. 2's factor: (1 - m/2) - (m/2) cos(2 pi f_m t), with cycles = f_m t."""
    return (1 - m / 2) - (m / 2) * np.cos(2 * np.pi * cycles)


# --- fades (eq. 1) -----------------------------------------------------------------------


def test_fades_are_linear_and_frame_the_motion():
    resolved = plan_of(fade_in_s=0.5, fade_out_s=0.25)
    assert resolved.stroke_s == pytest.approx(2.75)
    t = np.linspace(0, 2.75, 1101, endpoint=False)
    expected = np.minimum(np.minimum(t / 0.5, 1.0), (2.75 - t) / 0.25)
    np.testing.assert_allclose(envelope_at(resolved, t), expected, atol=EXACT)


def test_envelope_is_zero_outside_the_pattern():
    resolved = plan_of()
    env = envelope_at(resolved, np.array([-1.0, -1e-9, resolved.duration_s, 100.0]))
    np.testing.assert_array_equal(env, 0.0)


def test_every_stroke_has_its_own_fades():
    resolved = plan_of(repeat=3, alternate=True)
    stroke = resolved.stroke_s
    t = np.linspace(0, stroke, 777, endpoint=False)
    first = envelope_at(resolved, t)
    for k in (1, 2):
        np.testing.assert_allclose(envelope_at(resolved, t + k * stroke), first, atol=SHIFTED)
    # Silence at every stroke boundary, full amplitude in every stroke's middle.
    starts = np.arange(3) * stroke
    np.testing.assert_allclose(envelope_at(resolved, starts), 0.0, atol=SHIFTED)
    np.testing.assert_allclose(envelope_at(resolved, starts + stroke / 2), 1.0, atol=EXACT)


# --- amplitude modulation (eq. 2) ------------------------------------------------------


def test_eq2_with_m_1_is_zero_at_the_stroke_start_and_full_in_its_middle():
    for fades in (0.0, 0.6):
        resolved = plan_of(
            modulation={"index": 1.0, "freq_hz": "stroke"}, fade_in_s=fades, fade_out_s=fades
        )
        stroke = resolved.stroke_s
        env = envelope_at(resolved, np.array([0.0, stroke / 2]))
        np.testing.assert_allclose(env, [0.0, 1.0], atol=EXACT)


@pytest.mark.parametrize("m", [0.0, 0.25, 0.5, 0.8, 1.0])
def test_eq2_follows_its_formula_over_the_stroke(m):
    # Without fades the envelope is eq. 2 alone; one period spans the stroke.
    resolved = plan_of(
        modulation={"index": m, "freq_hz": "stroke"}, fade_in_s=0.0, fade_out_s=0.0, repeat=2
    )
    stroke = resolved.stroke_s
    t = np.linspace(0, 2 * stroke, 2001, endpoint=False)
    expected = eq2(m, (t % stroke) / stroke)
    np.testing.assert_allclose(envelope_at(resolved, t), expected, atol=SHIFTED)
    start, middle = envelope_at(resolved, np.array([0.0, stroke / 2]))
    assert start == pytest.approx(1 - m, abs=EXACT)
    assert middle == pytest.approx(1.0, abs=EXACT)


def test_eq2_with_fades_multiplies_the_fades():
    resolved = plan_of(modulation={"index": 0.6, "freq_hz": "stroke"})
    t = np.linspace(0, resolved.stroke_s, 1001, endpoint=False)
    fades = np.minimum(np.minimum(t / 0.6, 1.0), (resolved.stroke_s - t) / 0.6)
    expected = fades * eq2(0.6, t / resolved.stroke_s)
    np.testing.assert_allclose(envelope_at(resolved, t), expected, atol=SHIFTED)


def test_eq2_with_a_fixed_frequency_runs_on_pattern_time():
    resolved = plan_of(
        modulation={"index": 0.7, "freq_hz": 3.0}, fade_in_s=0.0, fade_out_s=0.0, repeat=2
    )
    t = np.linspace(0, resolved.duration_s, 3001, endpoint=False)
    np.testing.assert_allclose(envelope_at(resolved, t), eq2(0.7, 3.0 * t), atol=SHIFTED)


# --- positions -----------------------------------------------------------------------------


def test_point_rests_during_fades_and_moves_at_constant_speed():
    path = {"kind": "polyline", "points_cm": [[0.0, 0.0], [3.0, 4.0], [3.0, 14.0]]}
    resolved = plan_of(path=path, speed_cm_s=5.0, fade_in_s=0.4, fade_out_s=0.3)
    assert resolved.motion_s == pytest.approx(3.0)  # 5 + 10 cm at 5 cm/s
    fade_in = np.linspace(0, 0.4, 9)
    np.testing.assert_allclose(positions_at(resolved, fade_in)[0], [[0.0, 0.0]] * 9)
    fade_out = 0.4 + 3.0 + np.linspace(0, 0.3, 9, endpoint=False)
    np.testing.assert_allclose(positions_at(resolved, fade_out)[0], [[3.0, 14.0]] * 9)
    # Arc length travelled = speed x time since the motion began.
    t = 0.4 + np.linspace(0, 3.0, 61)
    s = 5.0 * (t - 0.4)
    expected = np.where(
        (s <= 5.0)[:, None],
        np.column_stack([0.6 * s, 0.8 * s]),
        np.column_stack([np.full_like(s, 3.0), 4.0 + (s - 5.0)]),
    )
    np.testing.assert_allclose(positions_at(resolved, t)[0], expected, atol=SHIFTED)


def test_alternate_strokes_run_backwards():
    resolved = plan_of(repeat=4, alternate=True, speed_cm_s=9.6)
    stroke = resolved.stroke_s
    local = np.linspace(0, stroke, 101, endpoint=False)
    forward = positions_at(resolved, local)[0]
    backward = positions_at(resolved, local + stroke)[0]
    # The backward stroke at time tau is where the forward one is at motion_s - tau.
    mirrored = positions_at(resolved, 2 * 0.6 + resolved.motion_s - local)[0]
    np.testing.assert_allclose(backward, mirrored, atol=SHIFTED)
    np.testing.assert_allclose(positions_at(resolved, local + 2 * stroke)[0], forward)
    np.testing.assert_allclose(forward[0], [1.9, 12.0])
    np.testing.assert_allclose(backward[0], [1.9, 2.4])


def test_repeat_without_alternate_restarts_at_the_start():
    resolved = plan_of(repeat=2)
    stroke = resolved.stroke_s
    local = np.linspace(0, stroke, 51, endpoint=False)
    np.testing.assert_allclose(
        positions_at(resolved, local + stroke)[0], positions_at(resolved, local)[0]
    )


def test_keyframe_intensity_is_interpolated_between_keyframes():
    path = {
        "kind": "keyframes",
        "keyframes": [
            {"t_s": 0.0, "x_cm": 0.0, "y_cm": 0.0, "intensity": 0.0},
            {"t_s": 1.0, "x_cm": 0.0, "y_cm": 4.8, "intensity": 1.0},
        ],
    }
    resolved = pt.plan(TouchPattern.model_validate({"path": path, "fade_in_s": 0.5}))
    points, intensity = positions_at(resolved, np.array([0.25, 0.5, 0.75, 1.5, 1.8]))
    np.testing.assert_allclose(intensity, [0.0, 0.0, 0.25, 1.0, 1.0])
    np.testing.assert_allclose(points[:, 1], [0.0, 0.0, 1.2, 4.8, 4.8])


# --- gains at control rate ---------------------------------------------------------------


def test_control_gains_are_position_gains_times_envelope_times_amplitude(rng):
    resolved = plan_of(
        modulation={"index": 0.5, "freq_hz": "stroke"},
        path={
            "kind": "arc",
            "start_cm": [3.8, 12.0],
            "through_cm": [0.0, 7.2],
            "end_cm": [3.8, 2.4],
        },
        repeat=2,
        alternate=True,
    )
    t = np.sort(rng.uniform(0, resolved.duration_s, 200))
    gains = control_gains(resolved, t)
    points, _ = positions_at(resolved, t)
    env = envelope_at(resolved, t)
    for k in range(len(t)):
        expected = pt.gains_at(None, *points[k]) * env[k] * resolved.amplitude
        np.testing.assert_allclose(gains[k], expected, atol=EXACT)
    # Power law: the channels' energy is the envelope's, wherever the point is.
    np.testing.assert_allclose(
        np.sqrt(np.sum(gains**2, axis=1)), env * resolved.amplitude, atol=EXACT
    )
