"""Interpolation laws and per-actuator gains for phantom points.

Laws (Schneider et al., UIST 2015, as in US10867526B2 eqs. 5-7; 1D from Israr & Poupyrev,
CHI 2011, eq. 4), for a weight ``w`` in [0, 1] of an actuator:

- ``linear``: ``w``            (sum of squares drops to 0.5 mid-edge, -3 dB)
- ``log``:    ``log2(1 + w)``  (safe at w = 0, unlike a dB crossfade)
- ``power``:  ``sqrt(w)``      (sum of squares is 1 everywhere: constant energy)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Law, Mode

LAWS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "linear": lambda w: w,
    "log": lambda w: np.log2(1.0 + w),
    "power": np.sqrt,
}


def apply_law(weights: np.ndarray, law: str) -> np.ndarray:
    """Map weights in [0, 1] to amplitude factors with ``law``."""
    try:
        return LAWS[law](weights)
    except KeyError:
        raise ParameterError(f"law={law!r} must be one of {sorted(LAWS)}") from None


def gains_for_points(
    geometry: Geometry, points_cm: np.ndarray, *, law: str, mode: str
) -> tuple[np.ndarray, np.ndarray]:
    """Gains of every output channel for many phantom points.

    Parameters
    ----------
    geometry : Geometry
    points_cm : ndarray, shape (n, 2), finite, columns x_cm and y_cm
    law : {"linear", "log", "power"}
    mode : {"1d", "2d"}
        ``"2d"``: barycentric weights in the point's triangle. ``"1d"``: only y counts;
        both actuators of a row get the row's gain, as in the paper.

    Returns
    -------
    gains : ndarray, shape (n, channels), float64, each in [0, 1]
    distance_cm : ndarray, shape (n,)
        How far each point was projected onto the layout (0 inside).
    """
    points = np.asarray(points_cm, dtype=np.float64).reshape(-1, 2)
    if mode == "2d":
        gains = np.zeros((len(points), geometry.channels))
        triangle, weights, distance = geometry.barycentric(points)
        columns = geometry.columns[geometry.triangles[triangle]]  # (n, 3)
        gains[np.arange(len(points))[:, None], columns] = apply_law(weights, law)
    elif mode == "1d":
        lower, beta, distance = geometry.row_weights(points[:, 1])
        rows = geometry.row_channels  # (rows, channels): 1 where an actuator of the row sits
        gains = apply_law(1.0 - beta, law)[:, None] * rows[lower]
        gains += apply_law(beta, law)[:, None] * rows[lower + 1]
    else:
        raise ParameterError(f"mode={mode!r} must be '1d' or '2d'")
    return gains, distance


def gains_at(
    device: DeviceProfile | None,
    x_cm: float,
    y_cm: float,
    *,
    law: Law = "power",
    mode: Mode = "2d",
) -> np.ndarray:
    """Relative amplitude of every output channel for a phantom point at (x_cm, y_cm).

    Parameters
    ----------
    device : DeviceProfile or None
        None: ``DeviceProfile.default()``, the paper's armband.
    x_cm, y_cm : float, finite, within ±1000 cm (``limits.MAX_COORD_CM``, as path points)
        Position of the point; outside the layout it is projected onto it.
    law : {"linear", "log", "power"}, default "power"
    mode : {"1d", "2d"}, default "2d"

    Returns
    -------
    ndarray, shape (channels,), float64
        Gains in [0, 1]; at most 3 (2D) or 2 rows (1D) are non-zero.
    """
    cap = limits.MAX_COORD_CM
    if not (np.isfinite(x_cm) and np.isfinite(y_cm) and max(abs(x_cm), abs(y_cm)) <= cap):
        raise ParameterError(f"x_cm={x_cm!r}, y_cm={y_cm!r} must be finite and within ±{cap:g} cm")
    geometry = Geometry.for_device(device or DeviceProfile.default())
    gains, _ = gains_for_points(geometry, np.array([[x_cm, y_cm]]), law=law, mode=mode)
    return gains[0]
