"""Hypothesis strategies shared by the test modules: layouts, paths and patterns."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import reject
from hypothesis import strategies as st
from pydantic import ValidationError

from phantomtouch.schema import DeviceProfile


def _grid_cm(low_mm: int, high_mm: int) -> st.SearchStrategy[float]:
    """Coordinates on a 1 mm grid: exact collinear and symmetric layouts come up often."""
    return st.integers(low_mm, high_mm).map(lambda mm: mm / 10.0)


@st.composite
def layouts(draw: st.DrawFn) -> DeviceProfile:
    """Custom actuator layouts (Delaunay-triangulated) that the schema accepts.

    3 to 8 actuators on a 1 mm grid within 12 x 16 cm, wired to a shuffled set of
    channels; duplicate or collinear layouts are refused by the schema and skipped here.
    """
    n = draw(st.integers(3, 8))
    points = draw(
        st.lists(
            st.tuples(_grid_cm(-20, 100), _grid_cm(-20, 140)),
            min_size=n,
            max_size=n,
            unique=True,
        )
    )
    channels = draw(st.permutations(list(range(1, n + 1))))
    actuators = [
        {"x_cm": x, "y_cm": y, "channel": c} for (x, y), c in zip(points, channels, strict=True)
    ]
    try:
        return DeviceProfile.model_validate({"name": "random", "actuators": actuators})
    except ValidationError:
        reject()


def channel_positions(device: DeviceProfile) -> np.ndarray:
    """Actuator position of each output channel, shape (channels, 2)."""
    positions = np.full((device.channels, 2), np.nan)
    for actuator in device.actuators:
        positions[actuator.channel - 1] = (actuator.x_cm, actuator.y_cm)
    return positions


_x = st.floats(-1.0, 4.8, allow_nan=False)
_y = st.floats(-1.0, 15.4, allow_nan=False)
_points = st.tuples(_x, _y)


PATH_KINDS = ("polyline", "arc", "spline", "keyframes")


def _arc_through(start: tuple[float, float], end: tuple[float, float], bulge: float) -> list[float]:
    """The point ``bulge`` cm off the middle of the chord, at right angles to it."""
    dx, dy = end[0] - start[0], end[1] - start[1]
    chord = float(np.hypot(dx, dy)) or 1.0
    middle = ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2)
    return [middle[0] - bulge * dy / chord, middle[1] + bulge * dx / chord]


@st.composite
def paths(draw: st.DrawFn, kinds: tuple[str, ...] = PATH_KINDS) -> dict[str, Any]:
    """Polyline, arc, spline or keyframe paths around (and a little outside) the armband."""
    kind = draw(st.sampled_from(kinds))
    if kind == "polyline":
        return {"kind": kind, "points_cm": draw(st.lists(_points, min_size=1, max_size=5))}
    if kind == "arc":
        start = draw(_points)
        end = draw(_points.filter(lambda p: np.hypot(p[0] - start[0], p[1] - start[1]) > 0.1))
        bulge = draw(st.one_of(st.floats(-4.0, -0.05), st.floats(0.05, 4.0)))
        through = _arc_through(start, end, bulge)
        return {"kind": kind, "start_cm": start, "through_cm": through, "end_cm": end}
    if kind == "spline":
        return {"kind": kind, "points_cm": draw(st.lists(_points, min_size=2, max_size=5))}
    steps = draw(st.lists(st.floats(0.03, 0.1), min_size=0, max_size=4))
    start = draw(st.floats(0.0, 0.05))
    times = np.cumsum([start, *steps]).tolist()
    return {
        "kind": "keyframes",
        "keyframes": [
            {"t_s": t, "x_cm": draw(_x), "y_cm": draw(_y), "intensity": draw(st.floats(0, 1))}
            for t in times
        ],
    }


carriers = st.one_of(
    st.builds(lambda f: {"kind": "sine", "freq_hz": f}, st.floats(20.0, 1000.0)),
    st.builds(
        lambda lo, seed: {"kind": "noise", "low_hz": lo, "high_hz": lo * 6, "seed": seed},
        st.floats(20.0, 200.0),
        st.integers(0, 2**32 - 1),
    ),
    st.builds(
        lambda f, seed: {"kind": "combined", "freq_hz": f, "seed": seed},
        st.floats(20.0, 1000.0),
        st.integers(0, 2**32 - 1),
    ),
)


@st.composite
def patterns(draw: st.DrawFn, kinds: tuple[str, ...] = PATH_KINDS) -> dict[str, Any]:
    """Valid-looking pattern dicts that render in well under half a second of audio."""
    path = draw(paths(kinds))
    fade_in = draw(st.floats(0.0, 0.05))
    fade_out = draw(st.floats(0.0, 0.05))
    repeat = draw(st.integers(1, 3))
    pattern: dict[str, Any] = {
        "path": path,
        "fade_in_s": fade_in,
        "fade_out_s": fade_out,
        "repeat": repeat,
        "alternate": draw(st.booleans()),
        "carrier": draw(carriers),
        "intensity": draw(st.one_of(st.sampled_from(["low", "high"]), st.floats(0.0, 1.0))),
        "law": draw(st.sampled_from(["linear", "log", "power"])),
        "mode": draw(st.sampled_from(["1d", "2d"])),
    }
    if draw(st.booleans()):
        pattern["modulation"] = {
            "index": draw(st.floats(0.0, 1.0)),
            "freq_hz": draw(st.one_of(st.just("stroke"), st.floats(0.5, 50.0))),
        }
    if path["kind"] != "keyframes":
        per_stroke = fade_in + fade_out + draw(st.floats(0.02, 0.15))
        pattern["duration_s"] = per_stroke * repeat
    return pattern
