"""Receiver proximities to live contacts: clusters, weighted positions, smoothing.

Each instant the receivers whose proximity is at least ``threshold`` are *active*.
Active receivers closer than ``cluster_gap_cm`` to one another (directly or through a
chain of active receivers) belong to one touch; the two touches with the most summed
proximity become live contacts, each at the proximity-weighted mean of its receivers'
positions ``sum(p_i r_i) / sum(p_i)``, with intensity ``max_intensity * min(1, sum(p_i))``.
Receivers whose spheres overlap so that two neighbours' proximities sum to about 1
(radius = their spacing) give a point that glides between them at an even intensity:
at a fraction ``f`` of the way from receiver A to B, ``p_A = 1 - f`` and ``p_B = f``,
and the weighted mean is exactly the hand's position.

Every contact's position and intensity pass a one-pole low-pass of time constant
``smoothing_s`` (at most one 90 Hz frame, 11.1 ms): ``s += (1 - exp(-dt / tau)) (target - s)``
with ``dt`` the time since the contact's last update. On a ramp it lags by ``tau``; a
contact's first update is not smoothed (it starts where the touch is).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np

MAX_CONTACTS = 2
"""Live contacts the receivers may become at once: two separate touches."""


@dataclass(frozen=True)
class Touch:
    """One cluster of active receivers: where it is and how strongly it is touched."""

    x_cm: float
    y_cm: float
    intensity: float
    weight: float
    """Summed proximity of its receivers (which of several touches are kept)."""


class ReceiverLayout:
    """Where the receivers are and which are neighbours (closer than ``gap_cm``).

    The neighbours are found once; each instant then costs a walk over the active
    receivers only (a few microseconds for an avatar's dozen).

    Parameters
    ----------
    positions_cm : ndarray, shape (n, 2)
        Receiver positions (x_cm, y_cm).
    gap_cm : float, > 0
    """

    def __init__(self, positions_cm: np.ndarray, gap_cm: float) -> None:
        points = np.asarray(positions_cm, dtype=np.float64)
        self.positions_cm = [(float(x), float(y)) for x, y in points]
        distance = np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))
        close = distance < gap_cm
        self.neighbours = [
            [int(j) for j in np.flatnonzero(row) if j != i] for i, row in enumerate(close)
        ]

    def touches(
        self, proximity: list[float], *, threshold: float, max_intensity: float
    ) -> list[Touch]:
        """The touches the receivers report, the strongest first, at most
        :data:`MAX_CONTACTS`.

        Parameters
        ----------
        proximity : list of float, one per receiver, each in [0, 1]
        threshold : float, 0 <= threshold < 1
        max_intensity : float, 0 < max_intensity <= 1
        """
        active = {i for i, p in enumerate(proximity) if p > 0.0 and p >= threshold}
        found = []
        while active:
            cluster = [active.pop()]
            for i in cluster:  # grows while it is walked: a breadth-first search
                for j in self.neighbours[i]:
                    if j in active:
                        active.remove(j)
                        cluster.append(j)
            weight = x_sum = y_sum = 0.0
            for i in cluster:
                p = proximity[i]
                x, y = self.positions_cm[i]
                weight += p
                x_sum += p * x
                y_sum += p * y
            found.append(
                Touch(x_sum / weight, y_sum / weight, max_intensity * min(1.0, weight), weight)
            )
        found.sort(key=lambda t: -t.weight)
        return found[:MAX_CONTACTS]


@dataclass
class Tracked:
    """A live contact the receivers hold down: its smoothed state."""

    contact: str
    x_cm: float
    y_cm: float
    intensity: float
    updated_s: float


@dataclass(frozen=True)
class Change:
    """What the engine is told: ``down``, ``move`` or ``up`` of ``contact``."""

    kind: str
    contact: str
    x_cm: float = 0.0
    y_cm: float = 0.0
    intensity: float = 0.0


class ContactTracker:
    """Keeps the receivers' live contacts across instants: matching and smoothing.

    Parameters
    ----------
    smoothing_s : float, >= 0
        Time constant of the low-pass; 0 passes the targets unchanged.
    prefix : str
        Contact ids are ``prefix + "0"`` and ``prefix + "1"``.
    """

    def __init__(self, smoothing_s: float, *, prefix: str = "receivers-") -> None:
        self.smoothing_s = smoothing_s
        self.ids = [f"{prefix}{k}" for k in range(MAX_CONTACTS)]
        self.filters: dict[str, Tracked] = {}
        """The smoothing state of each contact it put down; whether the contact is still
        down is the engine's to say (:meth:`keep_only`)."""

    def update(self, found: list[Touch], now_s: float) -> list[Change]:
        """The changes that take the live contacts to ``found`` (from :func:`touches`)."""
        changes: list[Change] = []
        unmatched = list(found)
        for contact in sorted(self.filters, key=lambda c: self.ids.index(c)):
            tracked = self.filters[contact]
            if not unmatched:
                del self.filters[contact]
                changes.append(Change("up", contact))
                continue
            nearest = min(
                unmatched, key=lambda t: math.hypot(t.x_cm - tracked.x_cm, t.y_cm - tracked.y_cm)
            )
            unmatched.remove(nearest)
            self._smooth(tracked, nearest, now_s)
            changes.append(Change("move", contact, tracked.x_cm, tracked.y_cm, tracked.intensity))
        for touch in unmatched:
            contact = next(c for c in self.ids if c not in self.filters)
            self.filters[contact] = Tracked(contact, touch.x_cm, touch.y_cm, touch.intensity, now_s)
            changes.append(Change("down", contact, touch.x_cm, touch.y_cm, touch.intensity))
        return changes

    def _smooth(self, tracked: Tracked, target: Touch, now_s: float) -> None:
        dt_s = max(0.0, now_s - tracked.updated_s)
        tracked.updated_s = now_s
        alpha = 1.0 if self.smoothing_s <= 0.0 else 1.0 - math.exp(-dt_s / self.smoothing_s)
        tracked.x_cm += alpha * (target.x_cm - tracked.x_cm)
        tracked.y_cm += alpha * (target.y_cm - tracked.y_cm)
        tracked.intensity += alpha * (target.intensity - tracked.intensity)

    def keep_only(self, down: Collection[str]) -> None:
        """Forget the smoothing state of every contact not in ``down`` (what the engine's
        front holds of the sender: a contact let go of by a stop, a deadline or a quota
        touches down again on the next update)."""
        for contact in [c for c in self.filters if c not in down]:
            del self.filters[contact]
