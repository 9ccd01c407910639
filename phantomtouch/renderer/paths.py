"""Resolve a path specification into a dense polyline with arc lengths.

Arcs and splines are sampled finely enough that the polyline's length matches the
curve's to better than 1e-5 relative; a polyline is kept as given.

Near-coincident points are merged before anything is fitted through them, for every
path kind (docs/algorithms.md, "Paths at the float's edge"): a point closer than
:data:`MERGE_REL` times the path's scale to the point kept before it is that point.
The scale is the path's largest absolute coordinate or the length of the polyline
through its points, whichever is larger, and at least 1 cm; so on the armband points
within 1e-12 cm are one point, and a spline's chord-length parameter strictly increases
by far more than a float's resolution of the path's length. A path whose points all
merge is a touch that does not move, whatever its kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.schema import limits
from phantomtouch.schema.pattern import ArcPath, KeyframePath, PathSpec, PolylinePath, SplinePath

_ARC_STEP_RAD = np.deg2rad(0.5)
_SPLINE_SAMPLES_PER_SEGMENT = 32
_SPLINE_MAX_SAMPLES = 200_000
_COLLINEAR_TOL = 1e-9
MERGE_REL = 1e-12
"""Points closer than this times the path's scale (at least 1 cm) are one point. Far
above a float's resolution (2.2e-16 relative) and far below the armband's (0.1 cm)."""
_MIN_SCALE_CM = 1.0


@dataclass(frozen=True)
class ResolvedPath:
    """A path as vertices in order of travel.

    Attributes
    ----------
    points_cm : ndarray, shape (n, 2)
    length_cm : ndarray, shape (n,), cumulative arc length at each vertex (0 first)
    times_s : ndarray, shape (n,) or None, keyframe times (keyframe paths only)
    intensity : ndarray, shape (n,) or None, keyframe intensities (keyframe paths only)
    """

    points_cm: np.ndarray
    length_cm: np.ndarray
    times_s: np.ndarray | None = None
    intensity: np.ndarray | None = None

    @property
    def total_length_cm(self) -> float:
        return float(self.length_cm[-1])


def _cumulative_length(points: np.ndarray) -> np.ndarray:
    steps = np.hypot(*np.diff(points, axis=0).T) if len(points) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(steps)])


def merge_tolerance_cm(points: np.ndarray) -> float:
    """How close two consecutive points of ``points`` (shape (n, 2)) may be and stay two."""
    if not np.all(np.isfinite(points)):
        raise ParameterError("path: its points must be finite numbers (cm)")
    largest = float(np.max(np.abs(points), initial=0.0))
    return MERGE_REL * max(_MIN_SCALE_CM, largest, float(_cumulative_length(points)[-1]))


def merged_into(points: np.ndarray) -> np.ndarray:
    """For each point, the index of the point it merges into (its own when kept).

    A point within :func:`merge_tolerance_cm` of the point kept before it merges into
    that point; so kept points are pairwise farther apart than the tolerance where they
    follow each other, and a run of close points is kept as its first.

    Returns
    -------
    ndarray of int, shape (n,), non-decreasing, ``out[i] <= i``
    """
    tol = merge_tolerance_cm(points)
    into = np.arange(len(points))
    if len(points) < 2 or np.all(np.hypot(*np.diff(points, axis=0).T) > tol):
        return into  # the usual case, decided without a loop
    kept = 0
    for i in range(1, len(points)):  # a run's later points may come back near its first
        if math.hypot(*(points[i] - points[kept])) <= tol:
            into[i] = kept
        else:
            kept = i
    return into


def _merged(points: np.ndarray) -> np.ndarray:
    return points[np.unique(merged_into(points))]


def _arc(path: ArcPath) -> np.ndarray:
    p0, p1, p2 = (
        np.array(p, dtype=np.float64) for p in (path.start_cm, path.through_cm, path.end_cm)
    )
    tol = merge_tolerance_cm(np.array([p0, p1, p2]))
    close = [math.hypot(*(a - b)) <= tol for a, b in ((p0, p1), (p1, p2), (p0, p2))]
    if close[0] and close[1]:
        return p0[None, :]  # all three are one point: a touch that does not move
    d1, d2 = p1 - p0, p2 - p0
    cross = d1[0] * d2[1] - d1[1] * d2[0]
    scale = max(float(np.dot(d1, d1)), float(np.dot(d2, d2)))
    if any(close) or abs(cross) <= _COLLINEAR_TOL * scale:
        field = "end_cm" if close[2] else "through_cm"
        raise ParameterError(
            f"path.{field}={list(map(float, p2 if close[2] else p1))}: start_cm, through_cm "
            "and end_cm are collinear or coincide; an arc needs three points on a circle "
            "(use a polyline for a straight stroke)"
        )
    # Circumcentre relative to p0.
    b = np.array([np.dot(d1, d1), np.dot(d2, d2)]) / 2.0
    centre = p0 + np.linalg.solve(np.array([d1, d2]), b)
    radius = float(np.hypot(*(p0 - centre)))
    angle0, angle1, angle2 = (float(np.arctan2(*(p - centre)[::-1])) for p in (p0, p1, p2))
    sweep = (angle2 - angle0) % (2 * np.pi)
    through = (angle1 - angle0) % (2 * np.pi)
    if through > sweep:  # the through point lies on the other way round
        sweep -= 2 * np.pi
    steps = max(8, int(np.ceil(abs(sweep) / _ARC_STEP_RAD)))
    angles = angle0 + sweep * np.linspace(0.0, 1.0, steps + 1)
    points = centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    points[0], points[-1] = p0, p2
    return points


def _spline(path: SplinePath) -> np.ndarray:
    points = _merged(np.array(path.points_cm, dtype=np.float64))
    if len(points) <= 2:
        return points
    chord = _cumulative_length(points)
    from scipy.interpolate import CubicSpline  # only spline paths need it (0.3 s to import)

    spline = CubicSpline(chord, points, axis=0, bc_type="natural")
    per_segment = max(1, min(_SPLINE_SAMPLES_PER_SEGMENT, _SPLINE_MAX_SAMPLES // (len(points) - 1)))
    s = np.concatenate(
        [
            np.linspace(chord[i], chord[i + 1], per_segment, endpoint=False)
            for i in range(len(points) - 1)
        ]
        + [chord[-1:]]
    )
    dense = np.asarray(spline(s))
    dense[-1] = points[-1]
    return dense


def resolve_path(path: PathSpec) -> ResolvedPath:
    """Turn a path specification into vertices and cumulative arc lengths.

    Near-coincident points are merged first (:func:`merged_into`); keyframes keep their
    times, a merged one stays where the keyframe before it is.

    Raises
    ------
    ParameterError
        An arc's three points are collinear or two of them coincide, or the resolved
        path is too large.
    """
    if isinstance(path, PolylinePath):
        points = _merged(np.array(path.points_cm, dtype=np.float64))
    elif isinstance(path, ArcPath):
        points = _arc(path)
    elif isinstance(path, SplinePath):
        points = _spline(path)
    elif isinstance(path, KeyframePath):
        given = np.array([(k.x_cm, k.y_cm) for k in path.keyframes], dtype=np.float64)
        points = given[merged_into(given)]  # a keyframe near the one before is a pause
        return ResolvedPath(
            points_cm=points,
            length_cm=_cumulative_length(points),
            times_s=np.array([k.t_s for k in path.keyframes], dtype=np.float64),
            intensity=np.array([k.intensity for k in path.keyframes], dtype=np.float64),
        )
    else:  # pragma: no cover - the schema admits no other kind
        raise ParameterError(f"path.kind={getattr(path, 'kind', None)!r} is not supported")
    if len(points) > limits.MAX_TIMELINE_POINTS:
        raise ParameterError(
            f"path: path resolves to {len(points)} points; at most {limits.MAX_TIMELINE_POINTS}"
        )
    return ResolvedPath(points_cm=points, length_cm=_cumulative_length(points))
