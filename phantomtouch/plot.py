"""The paper's Fig. 3 view of a rendered pattern, as a PNG.

Three parts, sharing one colour per actuator:

- **armband map** (left): the actuators at their positions, numbered by their output
  channel, the triangulation, and the phantom path of the first stroke from its start
  (circle) to its end (arrow), with how many points were projected onto the layout;
- **envelope** (top right): the pattern's envelope (fades, amplitude modulation),
  normalised to 1, over the carrier's range;
- **gain lanes** (right): one lane per actuator, as in the paper's Fig. 3. In each lane the
  rendered signal (its min/max per pixel column, so a pattern of any length plots quickly)
  and its gain, normalised to the pattern's amplitude: a lane spans gain 0 to 1. Actuators
  with the same gain (both columns of a row in 1D mode) keep lanes of their own.

Needs the ``plot`` extra (matplotlib).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from phantomtouch.errors import ParameterError, install_hint
from phantomtouch.renderer.plan import Plan
from phantomtouch.renderer.trajectory import control_gains, envelope_at, positions_at

_COLUMNS = 1600


class TraceEnvelope:
    """Min and max of each channel over ``columns`` equal stretches of a render.

    Feed blocks in order with :meth:`add`; memory is O(columns x channels).
    """

    def __init__(self, frames: int, channels: int, columns: int = _COLUMNS) -> None:
        self.frames = frames
        self.columns = max(1, min(columns, frames))
        self.low = np.zeros((self.columns, channels), dtype=np.float32)
        self.high = np.zeros((self.columns, channels), dtype=np.float32)
        self._position = 0

    def add(self, block: np.ndarray) -> None:
        start = self._position
        self._position += len(block)
        column = (np.arange(start, self._position, dtype=np.int64) * self.columns) // self.frames
        np.minimum.at(self.low, column, block)
        np.maximum.at(self.high, column, block)


ARROW_CM = 0.8
"""Length of the arrow at the path's end, cm."""
LANE_HALF_HEIGHT = 0.42
"""Half the height of a lane that gain 1 fills (lanes are 1 apart)."""


def _colors(channels: int) -> list[tuple[float, float, float, float]]:
    import matplotlib

    palette = matplotlib.colormaps["tab10" if channels <= 10 else "tab20"]
    return [palette(k % palette.N) for k in range(channels)]


def _draw_armband(ax: Any, plan: Plan, points_cm: np.ndarray, colors: list[Any]) -> None:
    """The layout with channel numbers, the triangulation and the first stroke's path."""
    from matplotlib.collections import LineCollection

    device = plan.device
    positions = plan.geometry.positions_cm
    for triangle in plan.geometry.triangles:
        corners = positions[[*triangle, triangle[0]]]
        ax.plot(corners[:, 0], corners[:, 1], color="0.82", lw=0.8, zorder=1)
    path = np.asarray(points_cm)
    segments = np.stack([path[:-1], path[1:]], axis=1)
    if len(segments):
        line = LineCollection(list(segments), cmap="Greys", lw=2.6, zorder=3)
        line.set_array(np.linspace(0.35, 1.0, len(segments)))
        line.set_clim(0.0, 1.0)
        ax.add_collection(line)
    ax.plot(*path[0], "o", color="k", ms=7, zorder=4)
    steps_cm = np.hypot(*np.diff(path, axis=0).T)
    if steps_cm.sum() > 1e-9:
        end = int(np.flatnonzero(steps_cm > 1e-9)[-1]) + 1
        to_end_cm = np.cumsum(steps_cm[:end][::-1])[::-1]
        # The arrow's tail: the last point at least ARROW_CM (or a quarter of the path) back.
        tail = np.flatnonzero(to_end_cm >= min(ARROW_CM, to_end_cm[0] / 4))[-1]
        ax.annotate(
            "",
            xy=path[end],
            xytext=path[tail],
            arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 1.6, "mutation_scale": 18},
            zorder=4,
        )
    for actuator in device.actuators:
        ax.plot(
            actuator.x_cm,
            actuator.y_cm,
            "o",
            ms=19,
            color=colors[actuator.channel - 1],
            mec="k",
            mew=0.8,
            zorder=5,
        )
        ax.text(
            actuator.x_cm,
            actuator.y_cm,
            str(actuator.channel),
            ha="center",
            va="center",
            fontsize=9,
            fontweight="bold",
            color="white",
            zorder=6,
        )
    outside = plan.projected_points
    title = "armband (channel numbers)"
    if plan.strokes > 1:
        way = ", every second backwards" if plan.pattern.alternate else ""
        title += f"\nfirst of {plan.strokes} strokes{way}"
    if outside:
        title += f"\n{outside} point(s) projected, up to {plan.max_projection_cm:.1f} cm"
    ax.set_title(title, fontsize=10)
    ax.set_aspect("equal")
    margin_cm = 1.2
    x_all = np.concatenate([positions[:, 0], path[:, 0]])
    y_all = np.concatenate([positions[:, 1], path[:, 1]])
    ax.set_xlim(x_all.min() - margin_cm, x_all.max() + margin_cm)
    ax.set_ylim(y_all.min() - margin_cm, y_all.max() + margin_cm)
    ax.set_xlabel("x (cm, around the arm)")
    ax.set_ylabel("y (cm, wrist 0 → elbow)")


def save_plot(plan: Plan, traces: TraceEnvelope, path: str | Path) -> None:
    """Write the Fig. 3 view of a rendered plan (map, envelope, gain lanes) to an image."""
    import matplotlib.pyplot as plt

    fig = build_figure(plan, traces)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def pyplot() -> Any:
    """``matplotlib.pyplot`` on its file-only backend (Agg), for every figure of the
    project (the caller's thread).

    Raises
    ------
    ParameterError
        matplotlib is missing: the message names the ``plot`` extra that brings it.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise ParameterError(
            f"plot needs matplotlib, the plot extra: {install_hint('plot')}"
        ) from exc
    return plt


def build_figure(plan: Plan, traces: TraceEnvelope) -> Any:
    """The Fig. 3 view as a matplotlib ``Figure`` with three axes: map, envelope, lanes.

    Lane ``k`` (from the top, channel ``k + 1``) is centred at ``channels - 1 - k``; its
    gain curves are ``centre ± LANE_HALF_HEIGHT * gain / amplitude``.
    """
    plt = pyplot()
    times = np.linspace(0.0, plan.duration_s, 2000, endpoint=False)
    envelope = envelope_at(plan, times)
    amplitude = max(plan.amplitude, 1e-12)
    gains = control_gains(plan, times) / amplitude
    first_stroke_s = np.linspace(0.0, plan.stroke_s, 1000, endpoint=False)
    points, _ = positions_at(plan, first_stroke_s)
    colors = _colors(plan.channels)
    fig = plt.figure(figsize=(12, 9))
    grid = fig.add_gridspec(2, 2, width_ratios=[1, 3.2], height_ratios=[1, 4.2])
    ax_map = fig.add_subplot(grid[:, 0])
    ax_env = fig.add_subplot(grid[0, 1])
    ax_lanes = fig.add_subplot(grid[1, 1], sharex=ax_env)
    pattern = plan.pattern
    fig.suptitle(
        f"{pattern.carrier.kind} carrier, {plan.path_length_cm:.2f} cm at "
        f"{plan.speed_cm_s:.2f} cm/s, {plan.duration_s:.2f} s, law={pattern.law}, "
        f"mode={pattern.mode}, amplitude {plan.amplitude:.3g}"
    )
    _draw_armband(ax_map, plan, points, colors)
    ax_env.fill_between(times, -envelope, envelope, color="0.82", lw=0)
    ax_env.plot(times, envelope, color="k", lw=1)
    ax_env.set_ylim(-1.08, 1.08)
    ax_env.set_ylabel("envelope\n(normalised)")
    ax_env.tick_params(labelbottom=False)
    column_t = (np.arange(traces.columns) + 0.5) * plan.duration_s / traces.columns
    # The carrier's crest: rendered peak over the largest gain, so that the signal's
    # outline meets the gain curve (a sine's crest is 1, a noise's more).
    peak = float(np.max(np.abs([traces.low, traces.high])))
    crest = peak / max(float(gains.max()) * amplitude, 1e-12)
    scale = LANE_HALF_HEIGHT / max(crest * amplitude, 1e-12)
    labels = []
    for actuator in plan.device.actuators:
        ch = actuator.channel - 1
        centre = plan.channels - 1 - ch
        color = colors[ch]
        ax_lanes.axhline(centre, color="0.9", lw=0.6, zorder=0)
        ax_lanes.fill_between(
            column_t,
            centre + np.maximum(traces.low[:, ch] * scale, -LANE_HALF_HEIGHT),
            centre + np.minimum(traces.high[:, ch] * scale, LANE_HALF_HEIGHT),
            color=color,
            alpha=0.45,
            lw=0,
        )
        for sign in (1.0, -1.0):
            ax_lanes.plot(
                times, centre + sign * LANE_HALF_HEIGHT * gains[:, ch], color=color, lw=1.4
            )
        labels.append((centre, f"{actuator.channel}  ({actuator.x_cm:g}, {actuator.y_cm:g})"))
    ax_lanes.set_yticks([c for c, _ in labels], [text for _, text in labels])
    for tick, (_, text) in zip(ax_lanes.get_yticklabels(), labels, strict=True):
        tick.set_color(colors[int(text.split()[0]) - 1])
        tick.set_fontweight("bold")
    ax_lanes.set_ylim(-0.6, plan.channels - 0.4)
    ax_lanes.set_ylabel("channel (x, y cm): signal and normalised gain,\neach lane ±gain 0 to 1")
    ax_lanes.set_xlabel("time (s)")
    ax_lanes.set_xlim(0.0, plan.duration_s)
    fig.tight_layout()
    return fig
