"""Path resolution: polylines as given, arcs on their circle, splines through their points."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.paths import resolve_path
from phantomtouch.schema import ArcPath, KeyframePath, PolylinePath, SplinePath


def test_polyline_is_kept_and_its_length_is_the_sum_of_its_segments(rng):
    points = rng.uniform(-2, 16, size=(7, 2))
    resolved = resolve_path(PolylinePath(points_cm=[tuple(p) for p in points]))
    np.testing.assert_array_equal(resolved.points_cm, points)
    steps = np.sqrt(np.sum(np.diff(points, axis=0) ** 2, axis=1))
    np.testing.assert_allclose(resolved.length_cm, np.concatenate([[0], np.cumsum(steps)]))
    assert resolved.times_s is None


def test_arc_lies_on_its_circle_and_has_the_circle_segment_length(rng):
    for _ in range(50):
        centre = rng.uniform(-5, 5, size=2)
        radius = rng.uniform(0.5, 20)
        start = rng.uniform(-np.pi, np.pi)
        sweep = rng.uniform(0.1, 2 * np.pi - 0.1) * rng.choice([-1, 1])
        angles = start + sweep * np.array([0.0, rng.uniform(0.1, 0.9), 1.0])
        p0, p1, p2 = (tuple(centre + radius * np.array([np.cos(a), np.sin(a)])) for a in angles)
        resolved = resolve_path(ArcPath(start_cm=p0, through_cm=p1, end_cm=p2))
        points = resolved.points_cm
        # The ends are the given points; the others come from the circumcentre solve,
        # whose rounding grows with the radius but stays far below 1e-9 relative.
        np.testing.assert_allclose(points[[0, -1]], [p0, p2], atol=1e-12)
        np.testing.assert_allclose(np.hypot(*(points - centre).T), radius, rtol=1e-9)
        # Chords of at most 0.5 degrees fall short of the arc by (d theta)^2 / 24 < 4e-6.
        np.testing.assert_allclose(resolved.total_length_cm, radius * abs(sweep), rtol=1e-5)
        # The arc goes the way of the through point: it passes next to it.
        assert np.min(np.hypot(*(points - p1).T)) <= radius * np.deg2rad(0.5)


def test_arc_through_collinear_points_is_refused():
    with pytest.raises(ParameterError, match="start_cm, through_cm and end_cm are collinear"):
        resolve_path(ArcPath(start_cm=(0, 0), through_cm=(1, 1), end_cm=(2, 2)))


def test_spline_passes_through_its_points_and_is_no_shorter_than_their_polyline(rng):
    points = np.column_stack([rng.uniform(0, 3.8, 6), np.linspace(14, 1, 6)])
    resolved = resolve_path(SplinePath(points_cm=[tuple(p) for p in points]))
    for p in points:
        assert np.min(np.hypot(*(resolved.points_cm - p).T)) < 1e-9
    chords = np.sum(np.hypot(*np.diff(points, axis=0).T))
    assert resolved.total_length_cm >= chords


def test_two_point_spline_is_the_straight_segment():
    resolved = resolve_path(SplinePath(points_cm=[(1.0, 12.0), (1.0, 2.4)]))
    assert resolved.total_length_cm == pytest.approx(9.6, rel=1e-12)  # one hypot


def test_keyframes_keep_their_times_and_intensities():
    path = KeyframePath.model_validate(
        {
            "keyframes": [
                {"t_s": 0.0, "x_cm": 0, "y_cm": 0, "intensity": 0.5},
                {"t_s": 2.0, "x_cm": 3, "y_cm": 4},
            ]
        }
    )
    resolved = resolve_path(path)
    np.testing.assert_array_equal(resolved.times_s, [0.0, 2.0])
    np.testing.assert_array_equal(resolved.intensity, [0.5, 1.0])
    assert resolved.total_length_cm == pytest.approx(5.0)
