"""Receiver proximities to contacts: weighted position, clusters, smoothing lag."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phantomtouch.osc.receivers import ContactTracker, ReceiverLayout, Touch

ROW_CM = 4.8
LINE = np.array([(1.9, ROW_CM * i) for i in range(4)])
"""Four receivers along the middle of the arm, 4.8 cm apart."""


def linear(y_cm: float, radius_cm: float = ROW_CM) -> np.ndarray:
    """Proximity falling linearly to 0 at the radius."""
    return np.clip(1.0 - np.abs(LINE[:, 1] - y_cm) / radius_cm, 0.0, 1.0)


def found(p: np.ndarray, gap_cm: float = 6.2) -> list[Touch]:
    layout = ReceiverLayout(LINE, gap_cm)
    return layout.touches(list(p), threshold=0.01, max_intensity=0.6)


@pytest.mark.parametrize("y_cm", [0.0, 1.0, 2.4, 4.8, 7.0, 11.9, 14.4])
def test_overlapping_receivers_put_the_point_on_the_hand(y_cm: float) -> None:
    """Radius = spacing: p_A = 1 - f, p_B = f, so the weighted mean is the hand, at an even
    intensity."""
    (touch,) = found(linear(y_cm))
    assert touch.y_cm == pytest.approx(y_cm, abs=1e-12)
    assert touch.x_cm == pytest.approx(1.9)
    assert touch.intensity == pytest.approx(0.6)


def test_separate_clusters_become_two_touches_the_strongest_first() -> None:
    p = np.array([0.3, 0.0, 0.0, 0.9])
    first, second = found(p)
    assert (first.y_cm, second.y_cm) == (pytest.approx(14.4), pytest.approx(0.0))
    assert (first.intensity, second.intensity) == (pytest.approx(0.54), pytest.approx(0.18))
    # A gap wider than the rows joins them into one touch at their weighted mean.
    (joined,) = found(p, gap_cm=20.0)
    assert joined.y_cm == pytest.approx(0.9 * 14.4 / 1.2)
    # Three clusters: the weakest is left out.
    assert len(found(np.array([0.5, 0.0, 0.2, 0.0]), gap_cm=4.0)) == 2
    assert found(np.zeros(4)) == []


def test_smoothing_lags_a_ramp_by_its_time_constant() -> None:
    """A one-pole low-pass driven by a ramp settles at ``ramp(t - tau)``."""
    tau_s, dt_s, speed_cm_s = 0.005, 1.0 / 90.0 / 8, 10.0
    tracker = ContactTracker(tau_s)
    t_s = 0.0
    for _ in range(400):
        target = Touch(1.9, speed_cm_s * t_s, 0.5, 1.0)
        (change,) = tracker.update([target], t_s)
        t_s += dt_s
    # Sampled exactly, the discrete one-pole lags by dt / (1 - exp(-dt / tau)) - dt.
    alpha = 1.0 - math.exp(-dt_s / tau_s)
    lag_s = dt_s / alpha - dt_s
    assert change.kind == "move"
    assert speed_cm_s * (t_s - dt_s) - change.y_cm == pytest.approx(speed_cm_s * lag_s, rel=1e-6)
    assert lag_s < 1.0 / 90.0


def test_contacts_are_matched_to_the_nearest_touch_and_lifted() -> None:
    tracker = ContactTracker(0.0)
    a, b = Touch(1.9, 1.0, 0.5, 1.0), Touch(1.9, 13.0, 0.5, 0.5)
    assert [c.kind for c in tracker.update([a, b], 0.0)] == ["down", "down"]
    # The far touch becomes the stronger: the contacts keep their places.
    moved = tracker.update([Touch(1.9, 12.5, 0.5, 2.0), Touch(1.9, 1.5, 0.5, 1.0)], 0.01)
    assert {(c.contact, c.y_cm) for c in moved} == {("receivers-0", 1.5), ("receivers-1", 12.5)}
    assert [(c.kind, c.contact) for c in tracker.update([a], 0.02)] == [
        ("move", "receivers-0"),
        ("up", "receivers-1"),
    ]
    assert [c.kind for c in tracker.update([], 0.03)] == ["up"]
