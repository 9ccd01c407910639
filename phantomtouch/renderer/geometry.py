"""Triangulated actuator layouts: barycentric weights, projection, rows for 1D mode.

Numerical pitfalls handled here (docs/algorithms.md, sec. 9): weights come out slightly
negative on edges, so they are clipped and renormalised; a point outside the layout is
projected onto the nearest triangle first; neighbouring triangles share their edge
vertices, so weights agree on the edge and gains stay continuous.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from phantomtouch.errors import DeviceError
from phantomtouch.schema.device import DeviceProfile

_INSIDE_TOL = 1e-9
_ROW_TOL_CM = 1e-6
_ROUNDING_WEIGHT = 1e-12
"""Weights below this are rounding noise of a point on an edge or vertex: set to 0."""
_FLAT_DET_CM2 = 1e-9
"""Triangles whose edge determinant (twice the area) is below this are flat."""


@dataclass(frozen=True, eq=False)
class Geometry:
    """A device's layout prepared for fast lookups.

    Attributes
    ----------
    positions_cm : ndarray, shape (actuators, 2)
    triangles : ndarray of int, shape (triangles, 3), indices into ``positions_cm``
    columns : ndarray of int, shape (actuators,), output column (channel - 1) per actuator
    channels : int, number of output channels
    row_y_cm : ndarray, shape (rows,), distinct actuator y positions, increasing (1D mode)
    row_members : tuple of ndarray, actuator indices of each row
    row_channels : ndarray, shape (rows, channels), 1.0 where an actuator of the row sits
    """

    positions_cm: np.ndarray
    triangles: np.ndarray
    columns: np.ndarray
    channels: int
    row_y_cm: np.ndarray
    row_members: tuple[np.ndarray, ...]
    row_channels: np.ndarray
    _origin: np.ndarray  # (triangles, 2): first vertex of each triangle
    _inverse: np.ndarray  # (triangles, 2, 2): maps p - origin to (w1, w2)

    @classmethod
    def for_device(cls, device: DeviceProfile) -> Geometry:
        """The (cached) geometry of ``device``."""
        return _geometry(device)

    def barycentric(self, points_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Triangle and barycentric weights of each point, projecting outside points.

        Parameters
        ----------
        points_cm : ndarray, shape (n, 2), finite

        Returns
        -------
        triangle : ndarray of int, shape (n,)
            Index of the triangle that holds the (projected) point.
        weights : ndarray, shape (n, 3), float64
            Weights of that triangle's vertices, each in [0, 1], summing to 1.
        distance_cm : ndarray, shape (n,)
            How far each point was moved onto the layout (0 inside).
        """
        points = np.asarray(points_cm, dtype=np.float64).reshape(-1, 2)
        triangle, weights = self._locate(points)
        distance = np.zeros(len(points))
        outside = weights.min(axis=1) < -_INSIDE_TOL
        if np.any(outside):
            projected = self._project(points[outside])
            distance[outside] = np.hypot(*(projected - points[outside]).T)
            triangle[outside], weights[outside] = self._locate(projected)
        np.maximum(weights, 0.0, out=weights)  # in place, _locate made it: cheaper than np.clip
        np.minimum(weights, 1.0, out=weights)
        weights[weights < _ROUNDING_WEIGHT] = 0.0
        weights /= weights.sum(axis=1, keepdims=True)
        return triangle, weights, distance

    def row_weights(self, y_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """1D mode: the two rows around each y and their weights (1 - beta, beta).

        Returns
        -------
        lower : ndarray of int, shape (n,), index of the row below (or at) y
        beta : ndarray, shape (n,), relative position in [0, 1] towards the row above
        distance_cm : ndarray, shape (n,), how far y was clamped onto the rows' span
        """
        y = np.asarray(y_cm, dtype=np.float64).reshape(-1)
        rows = self.row_y_cm
        # np.maximum and np.minimum in place: np.clip costs more on a few dozen values
        clamped = np.maximum(y, rows[0])
        np.minimum(clamped, rows[-1], out=clamped)
        lower = np.searchsorted(rows, clamped, side="right")
        lower -= 1
        np.maximum(lower, 0, out=lower)
        np.minimum(lower, len(rows) - 2, out=lower)
        beta = (clamped - rows[lower]) / (rows[lower + 1] - rows[lower])
        np.maximum(beta, 0.0, out=beta)
        np.minimum(beta, 1.0, out=beta)
        distance = clamped - y
        return lower, beta, np.abs(distance, out=distance)

    def _locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dx = points[:, 0:1] - self._origin[None, :, 0]  # (n, triangles)
        dy = points[:, 1:2] - self._origin[None, :, 1]
        inv = self._inverse
        w1 = inv[:, 0, 0] * dx + inv[:, 0, 1] * dy
        w2 = inv[:, 1, 0] * dx + inv[:, 1, 1] * dy
        w0 = 1.0 - w1 - w2
        worst = np.minimum(np.minimum(w0, w1), w2)
        best = np.argmax(worst, axis=1)
        rows = np.arange(len(points))
        weights = np.stack([w0[rows, best], w1[rows, best], w2[rows, best]], axis=1)
        return best, weights

    def _project(self, points: np.ndarray) -> np.ndarray:
        """Nearest point of the triangulated area, for points outside it."""
        verts = self.positions_cm[self.triangles]  # (t, 3, 2)
        a = verts.reshape(-1, 2)
        b = np.roll(verts, -1, axis=1).reshape(-1, 2)
        ab = b - a
        rel = points[:, None, :] - a[None, :, :]
        t = np.clip((rel * ab).sum(axis=2) / (ab * ab).sum(axis=1), 0.0, 1.0)
        candidates = a[None] + t[:, :, None] * ab[None]
        dist2 = ((candidates - points[:, None, :]) ** 2).sum(axis=2)
        nearest = np.argmin(dist2, axis=1)
        return candidates[np.arange(len(points)), nearest]


@lru_cache(maxsize=32)
def _geometry(device: DeviceProfile) -> Geometry:
    positions = device.positions_cm()
    if device.triangles is not None:
        triangles = np.array(device.triangles, dtype=np.intp)
    else:
        from scipy.spatial import Delaunay, QhullError  # only custom layouts need it

        try:
            triangles = np.asarray(Delaunay(positions).simplices, dtype=np.intp)
        except QhullError as exc:
            raise DeviceError(f"device {device.name!r}: cannot triangulate layout: {exc}") from exc
    verts = positions[triangles]
    origin = verts[:, 0, :]
    edges = np.stack([verts[:, 1] - origin, verts[:, 2] - origin], axis=2)  # (t, 2, 2)
    flat = np.abs(np.linalg.det(edges)) < _FLAT_DET_CM2
    if device.triangles is None and not np.all(flat):
        # Qhull keeps zero-area triangles along collinear actuators on the hull's edge;
        # they cover no area, and their neighbours already hold those actuators.
        triangles, origin, edges = triangles[~flat], origin[~flat], edges[~flat]
    elif np.any(flat):
        raise DeviceError(f"device {device.name!r}: triangulation has a degenerate triangle")
    inverse = np.linalg.inv(edges)
    rows: list[float] = []
    for y in np.sort(positions[:, 1]):
        if not rows or y - rows[-1] > _ROW_TOL_CM:
            rows.append(float(y))
    row_y = np.array(rows)
    members = tuple(np.flatnonzero(np.abs(positions[:, 1] - y) <= _ROW_TOL_CM) for y in row_y)
    columns = np.array([a.channel - 1 for a in device.actuators], dtype=np.intp)
    row_channels = np.zeros((len(row_y), device.channels))
    for r, m in enumerate(members):
        row_channels[r, columns[m]] = 1.0
    return Geometry(
        positions_cm=positions,
        triangles=triangles,
        columns=columns,
        channels=device.channels,
        row_y_cm=row_y,
        row_members=members,
        row_channels=row_channels,
        _origin=origin,
        _inverse=inverse,
    )
