"""The --plot figure: an armband map with the path, one normalised gain lane per actuator."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.plot import LANE_HALF_HEIGHT, TraceEnvelope, build_figure

pytest.importorskip("matplotlib")


def figure_of(pattern: pt.TouchPattern) -> tuple[Any, pt.Plan]:
    plan = pt.plan(pattern)
    traces = TraceEnvelope(plan.frames, plan.channels)
    traces.add(pt.render(pattern))
    return build_figure(plan, traces), plan


def lane_curves(ax: Any, channels: int) -> dict[int, np.ndarray]:
    """Upper gain curve per channel (1-based), back in gain units."""
    curves: dict[int, np.ndarray] = {}
    for line in ax.get_lines():
        y = np.asarray(line.get_ydata(), dtype=float)
        if len(y) < 100:
            continue  # the lanes' baselines
        centre = float(np.round(np.median(y)))
        channel = channels - int(centre)
        gain = (y - centre) / LANE_HALF_HEIGHT
        if gain.max() > 0:
            curves[channel] = gain
    return curves


def test_map_numbers_the_actuators_at_their_positions_and_draws_the_path() -> None:
    fig, _ = figure_of(pt.preset("exp2/curved"))
    ax_map = fig.axes[0]
    labels = {t.get_text(): t.get_position() for t in ax_map.texts if t.get_text().isdigit()}
    assert labels == {
        str(a.channel): (a.x_cm, a.y_cm) for a in pt.DeviceProfile.default().actuators
    }
    # The path starts where the arc starts, (3.8, 12) cm, and its arrow ends at (3.8, 2.4).
    start = next(line for line in ax_map.get_lines() if line.get_marker() == "o")
    assert tuple(np.ravel(start.get_data())) == pytest.approx((3.8, 12.0))
    arrow = next(a for a in ax_map.texts if a.get_text() == "")
    assert tuple(arrow.xy) == pytest.approx((3.8, 2.4), abs=1e-6)
    assert fig.axes[2].get_legend() is None, "lanes are labelled; no legend over the curves"


def test_lanes_are_gains_normalised_to_the_amplitude() -> None:
    # A stroke along the x = 0 column passes through actuators 1-4: with the power law each
    # reaches gain 1 there (envelope 1 between the fades), the others stay at 0.
    pattern = pt.TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[0, 0], [0, 14.4]]}, "speed_cm_s": 4}
    )
    fig, plan = figure_of(pattern)
    curves = lane_curves(fig.axes[2], plan.channels)
    assert sorted(curves) == [1, 2, 3, 4]
    for channel in (2, 3):  # inner actuators: the path crosses them during the motion
        assert curves[channel].max() == pytest.approx(1.0, abs=0.01)


def test_1d_pairs_have_lanes_and_colours_of_their_own() -> None:
    fig, plan = figure_of(pt.preset("exp1/sine100-low-v10-am"))
    ax_lanes = fig.axes[2]
    curves = lane_curves(ax_lanes, plan.channels)
    assert sorted(curves) == list(range(1, 9))
    # 1D mode: both actuators of a row get the same gain, yet sit in different lanes.
    np.testing.assert_allclose(curves[1], curves[5], atol=1e-9)
    colours = {tuple(t.get_color()) for t in ax_lanes.get_yticklabels()}
    assert len(colours) == 8
