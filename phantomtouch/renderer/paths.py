"""Resolve a path specification into a dense polyline with arc lengths.

Arcs and splines are sampled finely enough that the polyline's length matches the
curve's to better than 1e-5 relative; a polyline is kept as given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.schema import limits
from phantomtouch.schema.pattern import ArcPath, KeyframePath, PathSpec, PolylinePath, SplinePath

_ARC_STEP_RAD = np.deg2rad(0.5)
_SPLINE_SAMPLES_PER_SEGMENT = 32
_SPLINE_MAX_SAMPLES = 200_000
_COLLINEAR_TOL = 1e-9


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


def _arc(path: ArcPath) -> np.ndarray:
    p0, p1, p2 = (
        np.array(p, dtype=np.float64) for p in (path.start_cm, path.through_cm, path.end_cm)
    )
    d1, d2 = p1 - p0, p2 - p0
    cross = d1[0] * d2[1] - d1[1] * d2[0]
    scale = max(float(np.dot(d1, d1)), float(np.dot(d2, d2)), 1e-300)
    if abs(cross) <= _COLLINEAR_TOL * scale:
        raise ParameterError(
            "path: start_cm, through_cm and end_cm are collinear or coincide; "
            "an arc needs three points on a circle (use a polyline for a straight stroke)"
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
    points = np.array(path.points_cm, dtype=np.float64)
    keep = np.concatenate([[True], np.any(np.diff(points, axis=0) != 0.0, axis=1)])
    points = points[keep]
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

    Raises
    ------
    ParameterError
        An arc's three points are collinear, or the resolved path is too large.
    """
    if isinstance(path, PolylinePath):
        points = np.array(path.points_cm, dtype=np.float64)
    elif isinstance(path, ArcPath):
        points = _arc(path)
    elif isinstance(path, SplinePath):
        points = _spline(path)
    elif isinstance(path, KeyframePath):
        points = np.array([(k.x_cm, k.y_cm) for k in path.keyframes], dtype=np.float64)
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
            f"path resolves to {len(points)} points; at most {limits.MAX_TIMELINE_POINTS}"
        )
    return ResolvedPath(points_cm=points, length_cm=_cumulative_length(points))
