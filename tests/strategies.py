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


@st.composite
def paths(draw: st.DrawFn, *, keyframes: bool = True) -> dict[str, Any]:
    """Polyline, arc, spline or keyframe paths around (and a little outside) the armband."""
    kinds = ["polyline", "arc", "spline"] + (["keyframes"] if keyframes else [])
    kind = draw(st.sampled_from(kinds))
    if kind == "polyline":
        return {"kind": kind, "points_cm": draw(st.lists(_points, min_size=1, max_size=5))}
    if kind == "arc":
        start, through, end = draw(_points), draw(_points), draw(_points)
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
def patterns(draw: st.DrawFn) -> dict[str, Any]:
    """Valid-looking pattern dicts that render in well under half a second of audio."""
    path = draw(paths())
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
