"""The paper's Fig. 3 view of a rendered pattern, as a PNG.

Three panels: the carrier with the pattern's envelope, the 8 actuator signals stacked
(drawn as their min/max per pixel column, so a pattern of any length plots quickly),
and the gain curves of the actuators over time. Needs the ``plot`` extra (matplotlib).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.plan import Plan
from phantomtouch.renderer.trajectory import control_gains, envelope_at

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


def save_plot(plan: Plan, traces: TraceEnvelope, path: str | Path) -> None:
    """Write the Fig. 3 view of a rendered plan to a PNG file."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise ParameterError("plot needs matplotlib: pip install 'phantomtouch[plot]'") from exc
    times = np.linspace(0.0, plan.duration_s, 2000, endpoint=False)
    envelope = envelope_at(plan, times) * plan.amplitude
    gains = control_gains(plan, times)
    fig, (ax_env, ax_sig, ax_gain) = plt.subplots(
        3, 1, figsize=(10, 9), sharex=True, gridspec_kw={"height_ratios": [1, 3, 1.4]}
    )
    pattern = plan.pattern
    ax_env.fill_between(times, -envelope, envelope, color="0.75", label="carrier range")
    ax_env.plot(times, envelope, color="k", lw=1, label="envelope")
    ax_env.set_ylabel("amplitude")
    ax_env.set_title(
        f"{pattern.carrier.kind} carrier, {plan.path_length_cm:.2f} cm at "
        f"{plan.speed_cm_s:.2f} cm/s, {plan.duration_s:.2f} s, "
        f"law={pattern.law}, mode={pattern.mode}"
    )
    column_t = (np.arange(traces.columns) + 0.5) * plan.duration_s / traces.columns
    scale = max(float(np.max(np.abs([traces.low, traces.high]))), 1e-12)
    colors = plt.get_cmap("tab10")
    for ch in range(plan.channels):
        offset = plan.channels - 1 - ch
        ax_sig.fill_between(
            column_t,
            offset + 0.45 * traces.low[:, ch] / scale,
            offset + 0.45 * traces.high[:, ch] / scale,
            color=colors(ch % 10),
            lw=0,
        )
        ax_gain.plot(times, gains[:, ch], color=colors(ch % 10), lw=1.2, label=f"{ch + 1}")
    ax_sig.set_yticks(
        range(plan.channels), [f"ch {plan.channels - k}" for k in range(plan.channels)]
    )
    ax_sig.set_ylabel(f"actuator signals (full height = {scale:.3g})")
    ax_gain.set_ylabel("gain x envelope")
    ax_gain.set_xlabel("time (s)")
    ax_gain.legend(title="channel", ncol=min(plan.channels, 8), fontsize="small", loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
