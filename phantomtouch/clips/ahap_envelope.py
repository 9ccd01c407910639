"""The ``.ahap`` envelopes on a grid of times, in time linear in the events (numpy).

Every corner of the continuous events (start, end of attack, start of release, end) is a
grid time, so between two grid times each event's envelope is a straight line and so is
their sum. The sum is carried across the grid as jumps (at a start without attack, an
end without release) and slope changes (at the ramps' corners), accumulated by
``cumsum``; where no event sounds it is exactly 0 (no rounding is carried over). A
dynamic parameter (a ``Parameter`` step or a ``ParameterCurve``) holds at a time the
value of the latest piece begun by then, found by a binary search. Each grid time has
two sides: ``left`` the limit from before it, ``right`` the value from it on.
"""

from __future__ import annotations

import numpy as np

SOUNDING = 1e-12
"""A summed envelope at or below this is silence (no event's sharpness is taken)."""


class Control:
    """One dynamic parameter over time: steps and ramps, the latest begun wins.

    Parameters
    ----------
    default : float
        The value before any piece begins.
    """

    def __init__(self, default: float) -> None:
        self.default = default
        self._pieces: list[tuple[float, np.ndarray, np.ndarray]] = []

    def add(self, times_s: np.ndarray, values: np.ndarray) -> None:
        """A piece from ``times_s[0]`` on: straight lines between the points, the last
        value held after them (one point: a step)."""
        self._pieces.append((float(times_s[0]), times_s, values))

    def corners(self) -> list[float]:
        """Every time at which a piece changes course, s."""
        return [float(t) for _, times, _ in self._pieces for t in times]

    def at(self, times_s: np.ndarray, *, left: bool) -> np.ndarray:
        """The value at each of ``times_s`` (increasing): the latest piece begun by then
        (strictly before, ``left``; of pieces begun at once the later in the file)."""
        values = np.full(len(times_s), self.default)
        if not self._pieces or len(times_s) == 0:
            return values
        pieces = sorted(self._pieces, key=lambda piece: piece[0])
        starts = np.array([piece[0] for piece in pieces])
        which = np.searchsorted(starts, times_s, side="left" if left else "right") - 1
        # ``which`` never decreases along ``times_s``: each piece owns one run of times.
        bounds = np.flatnonzero(np.diff(which)) + 1
        for begin, end in zip(
            np.concatenate(([0], bounds)), np.concatenate((bounds, [len(times_s)])), strict=True
        ):
            index = int(which[begin])
            if index >= 0:
                _, times, points = pieces[index]
                values[begin:end] = np.interp(times_s[begin:end], times, points)
        return values


def summed_envelope(
    grid_s: np.ndarray,
    starts_s: np.ndarray,
    ends_s: np.ndarray,
    attacks_s: np.ndarray,
    releases_s: np.ndarray,
    levels: np.ndarray,
    weights: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The continuous events' summed envelope and sharpness-weighted sum on ``grid_s``.

    Parameters
    ----------
    grid_s : ndarray, shape (n,), increasing
        Holds every event's ``start``, ``start + attack``, ``end - release`` and ``end``.
    starts_s, ends_s, attacks_s, releases_s, levels, weights : ndarray, shape (events,)
        Each event's times (s; ``attack + release <= end - start``), peak level, and
        peak level times its sharpness.

    Returns
    -------
    left, right, weighted_left, weighted_right : ndarray, shape (n,)
        The sum and the weighted sum at each grid time, from before and from it on.
    """
    n = len(grid_s)
    jumps = np.zeros(n)
    slopes = np.zeros(n)
    weighted_jumps = np.zeros(n)
    weighted_slopes = np.zeros(n)
    opened = np.zeros(n, dtype=np.int64)
    closed = np.zeros(n, dtype=np.int64)

    def index(times_s: np.ndarray) -> np.ndarray:
        return np.searchsorted(grid_s, times_s)

    def add(target: np.ndarray, times_s: np.ndarray, amounts: np.ndarray) -> None:
        np.add.at(target, index(times_s), amounts)

    ramped = attacks_s > 0.0
    safe_attack = np.where(ramped, attacks_s, 1.0)
    for values, jump, slope in (
        (levels, jumps, slopes),
        (weights, weighted_jumps, weighted_slopes),
    ):
        add(jump, starts_s[~ramped], values[~ramped])
        add(slope, starts_s[ramped], (values / safe_attack)[ramped])
        add(slope, (starts_s + attacks_s)[ramped], -(values / safe_attack)[ramped])
    released = releases_s > 0.0
    safe_release = np.where(released, releases_s, 1.0)
    for values, jump, slope in (
        (levels, jumps, slopes),
        (weights, weighted_jumps, weighted_slopes),
    ):
        add(jump, ends_s[~released], -values[~released])
        add(slope, (ends_s - releases_s)[released], -(values / safe_release)[released])
        add(slope, ends_s[released], (values / safe_release)[released])
    np.add.at(opened, index(starts_s), 1)
    np.add.at(closed, index(ends_s), 1)

    sounding_right = np.cumsum(opened - closed)
    sounding_left = sounding_right - opened + closed
    step_s = np.diff(grid_s)
    out: list[np.ndarray] = []
    for jump, slope in ((jumps, slopes), (weighted_jumps, weighted_slopes)):
        increments = jump.copy()
        increments[1:] += np.cumsum(slope)[:-1] * step_s
        right = np.cumsum(increments)
        left = right - jump
        right[sounding_right == 0] = 0.0
        left[sounding_left == 0] = 0.0
        out.extend((left, right))
    return out[0], out[1], out[2], out[3]


def kept_points(times_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Indices of the breakpoints that draw the same line: of each run of equal values,
    its first point and its last (when that lies at a later time)."""
    if len(values) == 0:
        return np.zeros(0, dtype=np.int64)
    starts = np.flatnonzero(np.concatenate(([True], values[1:] != values[:-1])))
    ends = np.concatenate((starts[1:] - 1, [len(values) - 1]))
    later = ends[times_s[ends] != times_s[starts]]
    return np.sort(np.concatenate((starts, later)))
