"""The six motor levels of a Tactosy sleeve equivalent to what plays, for the status.

The band plays a path point as a phantom at its exact place; a client reading the status
expects the levels a six-motor sleeve would show (``Status.ForearmL``: 3 columns at
``x`` 0, 0.5, 1 by 2 rows at ``y`` 0, 1, ``index = row * 3 + col``). A point is spread
over the motors around it by bilinear weights (its intensity on a motor it sits on, shared
by the two or four around a point between them); dots are their motors' levels; several
points take the largest level per motor. Pure; any thread.
"""

from __future__ import annotations

from collections.abc import Iterable

from phantomtouch.clips.tact_score import light

ARM_MOTORS = 6


def point_levels(x: float, y: float, intensity: float) -> list[float]:
    """The motor levels of one point at ``(x, y)`` (0-1 each) of ``intensity`` (0-100)."""
    levels = [0.0] * ARM_MOTORS
    light(levels, x, y, intensity)
    return levels


def combined(
    paths: Iterable[tuple[float, float, float]] = (), dots: Iterable[tuple[int, float]] = ()
) -> list[float]:
    """Levels 0-100 of path points ``(x, y, intensity)`` and dots ``(index, intensity)``
    together: the largest per motor; dot indices outside 0-5 are left out."""
    levels = [0.0] * ARM_MOTORS
    for x, y, intensity in paths:
        levels = [max(a, b) for a, b in zip(levels, point_levels(x, y, intensity), strict=True)]
    for index, intensity in dots:
        if 0 <= index < ARM_MOTORS:
            levels[index] = max(levels[index], intensity)
    return levels
