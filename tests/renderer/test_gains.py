"""Interpolation laws and phantom gains (docs/algorithms.md sec. 4, paper sec. III-A).

Every expected value comes from the laws themselves (power: sqrt(w), linear: w,
log: log2(1 + w); Tactile Brush eq. 4 in 1D) and from barycentric coordinates computed
here from the actuator positions, never from stored outputs of the renderer.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import phantomtouch as pt
from phantomtouch.errors import ParameterError
from phantomtouch.renderer.gains import apply_law, gains_for_points
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.schema import DeviceProfile
from tests.strategies import channel_positions, layouts

DEVICE = DeviceProfile.default()
POSITIONS = channel_positions(DEVICE)  # channel k - 1 -> actuator k's (x_cm, y_cm)
WIDTH_CM, LENGTH_CM = 3.8, 14.4
ROWS_Y_CM = (0.0, 4.8, 9.6, 14.4)

# Gains go through one sqrt/log of a weight that is exact to a few ulps (a 2 x 2 solve
# with coordinates below 15 cm): sums of squares and recovered points agree with the
# analytic values to far better than 1e-12.
EXACT = 1e-12


def reference_weights(x_cm: float, y_cm: float) -> np.ndarray:
    """Barycentric weights per channel, solved directly from the paper's triangles."""
    for triangle in DEVICE.triangles or ():
        corners = np.array([POSITIONS[DEVICE.actuators[k].channel - 1] for k in triangle])
        system = np.vstack([corners.T, np.ones(3)])
        weights = np.linalg.solve(system, [x_cm, y_cm, 1.0])
        if weights.min() >= -1e-12:
            per_channel = np.zeros(DEVICE.channels)
            for k, w in zip(triangle, weights, strict=True):
                per_channel[DEVICE.actuators[k].channel - 1] = max(w, 0.0)
            return per_channel
    raise AssertionError(f"({x_cm}, {y_cm}) lies in no triangle of the paper's layout")


def random_points(rng: np.random.Generator, n: int, margin_cm: float) -> np.ndarray:
    low = (-margin_cm, -margin_cm)
    high = (WIDTH_CM + margin_cm, LENGTH_CM + margin_cm)
    return rng.uniform(low, high, size=(n, 2))


def shared_edges(device: DeviceProfile) -> list[tuple[int, int]]:
    """Edges (actuator index pairs) that belong to two triangles of the layout."""
    geometry = Geometry.for_device(device)
    count: dict[tuple[int, int], int] = {}
    for triangle in geometry.triangles:
        for a, b in itertools.combinations(sorted(int(k) for k in triangle), 2):
            count[(a, b)] = count.get((a, b), 0) + 1
    return [edge for edge, n in count.items() if n == 2]


def min_altitude_cm(device: DeviceProfile) -> float:
    """Smallest altitude of any triangle: a weight changes by at most 1/h per cm."""
    geometry = Geometry.for_device(device)
    heights = []
    for triangle in geometry.triangles:
        a, b, c = geometry.positions_cm[triangle]
        area2 = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        longest = max(np.hypot(*(b - a)), np.hypot(*(c - b)), np.hypot(*(a - c)))
        heights.append(area2 / longest)
    return float(min(heights))


# --- power law (the paper's default) ---------------------------------------------------


def test_power_law_keeps_sum_of_squares_at_one_inside_and_outside(rng):
    for x, y in random_points(rng, 300, margin_cm=3.0):
        gains = pt.gains_at(DEVICE, x, y)
        assert gains.shape == (8,)
        assert np.all(gains >= 0.0)
        np.testing.assert_allclose(np.sum(gains**2), 1.0, rtol=0, atol=EXACT)


def test_power_law_weights_recover_the_point(rng):
    for x, y in random_points(rng, 300, margin_cm=0.0):
        weights = pt.gains_at(DEVICE, x, y) ** 2
        np.testing.assert_allclose(weights.sum(), 1.0, rtol=0, atol=EXACT)
        np.testing.assert_allclose(weights @ POSITIONS, [x, y], rtol=0, atol=EXACT)


def test_power_law_matches_square_root_of_barycentric_weights(rng):
    for x, y in random_points(rng, 200, margin_cm=0.0):
        expected = np.sqrt(reference_weights(x, y))
        # sqrt magnifies a weight's rounding near 0: sqrt(1e-16) = 1e-8.
        np.testing.assert_allclose(pt.gains_at(DEVICE, x, y), expected, rtol=0, atol=1e-7)


@pytest.mark.parametrize("law", ["power", "linear", "log"])
def test_point_on_an_actuator_drives_that_actuator_alone(law):
    for channel, (x, y) in enumerate(POSITIONS):
        gains = pt.gains_at(DEVICE, x, y, law=law)
        # log2(1 + 1) = sqrt(1) = 1: the actuator at full amplitude, every other exactly 0.
        assert gains[channel] == pytest.approx(1.0, abs=EXACT)
        assert np.count_nonzero(gains) == 1


@pytest.mark.parametrize("law", ["power", "linear", "log"])
def test_gains_are_continuous_across_every_shared_edge(law):
    edges = shared_edges(DEVICE)
    # 3 cells, each cut by its fixed diagonal, meeting at 2 inner rows: 5 shared edges.
    assert len(edges) == 5
    eps_cm = 1e-7
    # Weights are affine in the point with gradient at most 1/h (h the smallest altitude),
    # so the two points 2 eps apart differ by dw <= 2 eps / h in every weight. sqrt is
    # 1/2-Hoelder (|sqrt a - sqrt b| <= sqrt|a - b|), w is 1-Lipschitz, log2(1 + w) is
    # (1/ln 2)-Lipschitz; a jump between triangles would be of order 1 instead.
    dw = 2 * eps_cm / min_altitude_cm(DEVICE)
    bound = {"power": np.sqrt(dw), "linear": dw, "log": dw / np.log(2)}[law] + EXACT
    positions = Geometry.for_device(DEVICE).positions_cm
    for a, b in edges:
        pa, pb = positions[a], positions[b]
        normal = np.array([-(pb - pa)[1], (pb - pa)[0]]) / np.hypot(*(pb - pa))
        for t in np.linspace(0.05, 0.95, 19):
            on_edge = pa + t * (pb - pa)
            left = pt.gains_at(DEVICE, *(on_edge + eps_cm * normal), law=law)
            right = pt.gains_at(DEVICE, *(on_edge - eps_cm * normal), law=law)
            middle = pt.gains_at(DEVICE, *on_edge, law=law)
            assert np.max(np.abs(left - right)) <= bound
            assert np.max(np.abs(left - middle)) <= bound


# --- linear and logarithmic laws -------------------------------------------------------


def every_edge_midpoint() -> list[np.ndarray]:
    geometry = Geometry.for_device(DEVICE)
    edges = {
        tuple(sorted((int(a), int(b))))
        for triangle in geometry.triangles
        for a, b in itertools.combinations(triangle, 2)
    }
    return [(geometry.positions_cm[a] + geometry.positions_cm[b]) / 2 for a, b in edges]


def test_linear_law_drops_to_half_the_energy_mid_edge():
    for x, y in every_edge_midpoint():
        gains = pt.gains_at(DEVICE, x, y, law="linear")
        # w = 1/2 on two actuators: sum of squares 2 * 1/4 = 0.5, i.e. -3 dB.
        np.testing.assert_allclose(np.sum(gains**2), 0.5, rtol=0, atol=EXACT)
        np.testing.assert_allclose(np.sort(gains)[-2:], [0.5, 0.5], rtol=0, atol=EXACT)


def test_linear_and_log_laws_follow_the_barycentric_weights(rng):
    for x, y in random_points(rng, 200, margin_cm=0.0):
        w = reference_weights(x, y)
        np.testing.assert_allclose(pt.gains_at(DEVICE, x, y, law="linear"), w, atol=EXACT)
        np.testing.assert_allclose(pt.gains_at(DEVICE, x, y, law="log"), np.log2(1 + w), atol=EXACT)


def test_log_law_levels_mid_edge_and_at_the_centroid():
    for x, y in every_edge_midpoint():
        gains = pt.gains_at(DEVICE, x, y, law="log")
        level_db = 10 * np.log10(np.sum(gains**2))
        # 2 log2(1.5)^2 = 0.6845 -> -1.647 dB; docs/algorithms.md rounds it to -1.65 dB.
        assert level_db == pytest.approx(-1.65, abs=0.005)
    geometry = Geometry.for_device(DEVICE)
    for triangle in geometry.triangles:
        x, y = geometry.positions_cm[triangle].mean(axis=0)
        gains = pt.gains_at(DEVICE, x, y, law="log")
        np.testing.assert_allclose(np.sort(gains)[-3:], np.log2(4 / 3), atol=EXACT)
        # 3 log2(4/3)^2 = 0.5168 -> -2.867 dB; docs/algorithms.md gives -2.87 dB.
        assert 10 * np.log10(np.sum(gains**2)) == pytest.approx(-2.87, abs=0.005)


def test_log_law_is_finite_at_zero_weight():
    # A dB crossfade would give log(0) = -inf for the actuators a point does not use.
    gains = apply_law(np.array([0.0, 0.25, 1.0]), "log")
    np.testing.assert_array_equal(gains[[0, 2]], [0.0, 1.0])
    assert np.all(np.isfinite(pt.gains_at(DEVICE, 0.0, 0.0, law="log")))


def test_unknown_law_or_mode_is_refused_with_its_name():
    geometry = Geometry.for_device(DEVICE)
    with pytest.raises(ParameterError, match="law='cubic'"):
        gains_for_points(geometry, np.array([[1.0, 1.0]]), law="cubic", mode="2d")
    with pytest.raises(ParameterError, match="mode='3d'"):
        gains_for_points(geometry, np.array([[1.0, 1.0]]), law="power", mode="3d")


@pytest.mark.parametrize("x, y", [(np.nan, 1.0), (1.0, np.inf), (-np.inf, 0.0)])
def test_gains_at_refuses_non_finite_points(x, y):
    with pytest.raises(ParameterError, match="must be finite"):
        pt.gains_at(DEVICE, x, y)


# --- 1D mode: Tactile Brush between two rows --------------------------------------------


@pytest.mark.parametrize("row", [0, 1, 2])
@pytest.mark.parametrize("x", [0.0, 1.9, 3.8, 10.0])
def test_tactile_brush_values_at_beta_one_third(row, x):
    y = ROWS_Y_CM[row] + (ROWS_Y_CM[row + 1] - ROWS_Y_CM[row]) / 3  # beta = 1/3
    gains = pt.gains_at(DEVICE, x, y, mode="1d")
    lower = [row, 4 + row]  # channels (0-based) of the row below: both columns
    upper = [row + 1, 5 + row]
    # Tactile Brush eq. 4, power law: A1 = sqrt(1 - beta), A2 = sqrt(beta), here to the
    # six digits docs/algorithms.md gives.
    np.testing.assert_allclose(gains[lower], [0.816497, 0.816497], rtol=0, atol=1e-6)
    np.testing.assert_allclose(gains[upper], [0.57735, 0.57735], rtol=0, atol=1e-6)
    others = np.setdiff1d(np.arange(8), lower + upper)
    np.testing.assert_array_equal(gains[others], 0.0)
    linear = pt.gains_at(DEVICE, x, y, mode="1d", law="linear")
    np.testing.assert_allclose(linear[lower + upper], [2 / 3, 2 / 3, 1 / 3, 1 / 3], atol=EXACT)


def test_1d_mode_gives_both_actuators_of_a_row_the_same_gain(rng):
    for x, y in random_points(rng, 200, margin_cm=2.0):
        gains = pt.gains_at(DEVICE, x, y, mode="1d")
        np.testing.assert_array_equal(gains[:4], gains[4:])
        # One column alone is a two-actuator power crossfade: its energy is 1.
        np.testing.assert_allclose(np.sum(gains[:4] ** 2), 1.0, atol=EXACT)
        # Only y counts: the same y anywhere across the band gives the same gains.
        np.testing.assert_array_equal(gains, pt.gains_at(DEVICE, 1.9, y, mode="1d"))


# --- any layout --------------------------------------------------------------------------

COLLINEAR_HULL_LAYOUT = [
    (-4.5, -0.9),
    (0.7, -3.5),
    (4.7, 2.8),
    (-2.9, 4.3),
    (2.7, 4.4),
    (-4.0, 2.1),
    (-3.9, 2.3),  # on the hull edge from (-4.0, 2.1) to (-2.9, 4.3): Qhull adds a flat triangle
]


def _layout(points: list[tuple[float, float]]) -> DeviceProfile:
    actuators = [{"x_cm": x, "y_cm": y, "channel": i + 1} for i, (x, y) in enumerate(points)]
    return DeviceProfile.model_validate({"name": "example", "actuators": actuators})


@example(device=_layout(COLLINEAR_HULL_LAYOUT), seed=0)
@given(device=layouts(), seed=st.integers(0, 2**32 - 1))
def test_power_law_on_random_layouts(device, seed):
    rng = np.random.default_rng(seed)
    positions = channel_positions(device)
    used = ~np.isnan(positions[:, 0])
    # On an actuator: that actuator alone.
    for channel in np.flatnonzero(used):
        gains = pt.gains_at(device, *positions[channel])
        assert gains[channel] == pytest.approx(1.0, abs=EXACT)
        assert np.count_nonzero(gains) == 1
    # Convex combinations of the actuators lie in the hull, which Delaunay covers:
    # the weights (squared gains) give the point back.
    for _ in range(20):
        mix = rng.dirichlet(np.ones(used.sum()))
        point = mix @ positions[used]
        weights = pt.gains_at(device, *point) ** 2
        # Thin triangles of a random layout make the 2 x 2 solve less well conditioned.
        np.testing.assert_allclose(weights @ np.nan_to_num(positions), point, atol=1e-9)
        np.testing.assert_allclose(weights.sum(), 1.0, atol=EXACT)
    # Anywhere, inside or out: constant energy.
    low, high = positions[used].min(axis=0) - 3, positions[used].max(axis=0) + 3
    for x, y in rng.uniform(low, high, size=(20, 2)):
        gains = pt.gains_at(device, x, y)
        assert np.all(np.isfinite(gains))
        np.testing.assert_allclose(np.sum(gains**2), 1.0, atol=EXACT)
