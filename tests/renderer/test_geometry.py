"""Triangulated layouts: barycentric weights, projection onto the hull, rows for 1D."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch.errors import DeviceError
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.schema import DeviceProfile

DEVICE = DeviceProfile.default()
WIDTH_CM, LENGTH_CM = 3.8, 14.4
# Weights come from a 2 x 2 solve with coordinates below 20 cm, areas and distances from a
# few products: all exact to rounding, far below 1e-12.
EXACT = 1e-12


def layout(points, triangles=None) -> DeviceProfile:
    data = {
        "name": "test",
        "actuators": [{"x_cm": x, "y_cm": y, "channel": i + 1} for i, (x, y) in enumerate(points)],
    }
    if triangles is not None:
        data["triangles"] = triangles
    return DeviceProfile.model_validate(data)


def test_paper_layout_has_two_triangles_per_cell():
    geometry = Geometry.for_device(DEVICE)
    assert geometry.triangles.shape == (6, 3)
    assert geometry.channels == 8
    np.testing.assert_array_equal(geometry.row_y_cm, [0.0, 4.8, 9.6, 14.4])  # the paper's rows
    # Each cell is 3.8 x 4.8 cm: two triangles of half its area each.
    verts = geometry.positions_cm[geometry.triangles]
    a, b, c = verts[:, 0], verts[:, 1], verts[:, 2]
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    np.testing.assert_allclose(area, 3.8 * 4.8 / 2, rtol=EXACT)


def test_weights_inside_are_a_partition_of_unity_that_rebuilds_the_point(rng):
    geometry = Geometry.for_device(DEVICE)
    points = rng.uniform((0, 0), (WIDTH_CM, LENGTH_CM), size=(500, 2))
    triangle, weights, distance = geometry.barycentric(points)
    assert np.all((weights >= 0) & (weights <= 1))
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, rtol=0, atol=EXACT)
    corners = geometry.positions_cm[geometry.triangles[triangle]]  # (n, 3, 2)
    np.testing.assert_allclose(np.einsum("nk,nkd->nd", weights, corners), points, atol=EXACT)
    np.testing.assert_array_equal(distance, 0.0)


def test_points_outside_the_rectangle_are_projected_to_its_nearest_point(rng):
    geometry = Geometry.for_device(DEVICE)
    points = rng.uniform((-5, -5), (WIDTH_CM + 5, LENGTH_CM + 5), size=(500, 2))
    outside = (points[:, 0] < 0) | (points[:, 0] > WIDTH_CM)
    outside |= (points[:, 1] < 0) | (points[:, 1] > LENGTH_CM)
    points = points[outside]
    # The paper's layout covers exactly the rectangle: its nearest point is the clamp.
    nearest = np.clip(points, (0, 0), (WIDTH_CM, LENGTH_CM))
    triangle, weights, distance = geometry.barycentric(points)
    np.testing.assert_allclose(distance, np.hypot(*(points - nearest).T), atol=EXACT)
    corners = geometry.positions_cm[geometry.triangles[triangle]]
    np.testing.assert_allclose(np.einsum("nk,nkd->nd", weights, corners), nearest, atol=EXACT)


def test_row_weights_give_the_relative_position_between_rows():
    geometry = Geometry.for_device(DEVICE)
    y = np.array([-2.0, 0.0, 1.6, 4.8, 8.0, 14.4, 20.0])
    lower, beta, distance = geometry.row_weights(y)
    np.testing.assert_array_equal(lower, [0, 0, 0, 1, 1, 2, 2])
    np.testing.assert_allclose(beta, [0.0, 0.0, 1 / 3, 0.0, 2 / 3, 1.0, 1.0], atol=EXACT)
    np.testing.assert_allclose(distance, [2.0, 0, 0, 0, 0, 0, 5.6], atol=EXACT)


def test_non_convex_triangles_project_points_in_the_notch():
    # An L shape: two triangles meeting at (0, 0); the notch around (2, 2) is not covered.
    device = layout(
        [(0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (0.0, 4.0), (1.0, 4.0)],
        triangles=[(0, 1, 2), (0, 3, 4)],
    )
    geometry = Geometry.for_device(device)
    _, weights, distance = geometry.barycentric(np.array([[2.0, 2.0], [3.0, 0.5]]))
    assert distance[0] > 0.5  # outside both triangles, moved onto the nearer one
    assert distance[1] == 0.0
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=EXACT)


def test_delaunay_layout_with_collinear_actuators_on_its_hull():
    # Qhull returns a flat triangle through three collinear hull points; the layout is
    # still valid and must triangulate into triangles that all have an area.
    device = layout([(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (1.0, 1.5)])
    geometry = Geometry.for_device(device)
    verts = geometry.positions_cm[geometry.triangles]
    a, b, c = verts[:, 0], verts[:, 1], verts[:, 2]
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert np.all(area > 0.1)
    np.testing.assert_allclose(area.sum(), 0.5 * 2.0 * 1.5, rtol=EXACT)  # the hull's area
    assert set(geometry.triangles.ravel()) == {0, 1, 2, 3}


def test_explicit_flat_triangle_is_refused():
    # The schema refuses tiny triangles; the geometry double-checks what it is handed.
    device = layout([(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)], triangles=[(0, 1, 2)])
    flat = device.model_copy(update={"triangles": ((0, 1, 1),)})
    with pytest.raises(DeviceError, match="degenerate triangle"):
        Geometry.for_device(flat)
