"""The accuracy study as a terminal table and a work-precision plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from phantomtouch.analysis.accuracy import TWO_POINT_THRESHOLD_CM, AccuracyReport, Row
from phantomtouch.plot import pyplot

_HEADER = (
    ("setting", "{:<13}"),
    ("gain err max", "{:>12}"),
    ("gain err rms", "{:>12}"),
    ("pos err gains max/rms cm", "{:>24}"),
    ("level err dB", "{:>12}"),
    ("pos err twin max/rms cm", "{:>23}"),
    ("level var twin dB", "{:>17}"),
    ("CPU ms/s", "{:>8}"),
    ("x per-frame", "{:>11}"),
    ("engine ms/s", "{:>11}"),
    ("ok", "{:>3}"),
)


def _cells(row: Row) -> tuple[str, ...]:
    return (
        row.setting,
        f"{100 * row.gain_error_max:.2f} %",
        f"{100 * row.gain_error_rms:.3f} %",
        f"{row.position_error_gains_max_cm:.4f} / {row.position_error_gains_rms_cm:.4f}",
        f"{row.level_error_gains_max_db:.3f}",
        f"{row.position_error_twin_max_cm:.3f} / {row.position_error_twin_rms_cm:.3f}",
        f"{row.level_variation_twin_db:.3f}",
        f"{row.cpu_ms_per_s:.3f}",
        f"{row.cpu_relative:.3f}",
        f"{row.cpu_blocks_ms_per_s:.2f}",
        "yes" if row.meets_criteria else "no",
    )


def format_table(report: AccuracyReport) -> str:
    """The study as a plain-text table with a legend and the recommendation."""
    widths = [fmt for _, fmt in _HEADER]
    lines = [
        "  ".join(fmt.format(name) for name, fmt in _HEADER),
        *(
            "  ".join(f.format(c) for f, c in zip(widths, _cells(r), strict=True))
            for r in report.rows
        ),
        "",
        f"strokes: {', '.join(report.strokes)}; every error is the worst stroke's.",
        "gain err: |gain - per-frame gain| / amplitude, worst channel (max) and error energy "
        "/ signal energy (rms).",
        "pos err gains: energy centroid of the gains vs the intended (projected) path point.",
        f"pos err twin, level var twin: rendered signals -> actuator twin -> perceived "
        f"centroid and level over {1000 * report.window_s:g} ms windows; level var is the "
        "peak-to-peak deviation from the intended level.",
        "CPU ms/s: CPU time per second of audio, whole render (x per-frame: relative to "
        "gain_update_frames=1); engine ms/s: the same in the engine's block size.",
        f"ok: position within {report.criteria['position_error_max_cm']:g} cm and level "
        f"within {report.criteria['level_error_max_db']:g} dB (a tenth of the two-point "
        f"threshold, {TWO_POINT_THRESHOLD_CM:g} cm, and of the amplitude JND), ramped gains.",
        f"recommended default: {report.recommended or 'none meets the criteria'} "
        "(the cheapest that is ok).",
    ]
    return "\n".join(lines)


def save_plot(report: AccuracyReport, path: str | Path) -> None:
    """Work-precision plot: worst position and level error against CPU time per setting."""
    plt = pyplot()
    floor_cm, floor_db = 1e-4, 1e-4
    fig, (ax_pos, ax_level) = plt.subplots(1, 2, figsize=(12, 5))
    for row in report.rows:
        color = "tab:blue" if row.gain_ramp or row.gain_update_frames == 1 else "tab:orange"
        cpu = row.cpu_ms_per_s
        ax_pos.loglog(cpu, max(row.position_error_gains_max_cm, floor_cm), "o", color=color)
        ax_pos.loglog(cpu, row.position_error_twin_max_cm, "o", mfc="none", color=color)
        ax_level.loglog(cpu, max(row.level_error_gains_max_db, floor_db), "s", color=color)
        ax_level.loglog(cpu, row.level_variation_twin_db, "s", mfc="none", color=color)
        for ax, value in (
            (ax_pos, max(row.position_error_gains_max_cm, floor_cm)),
            (ax_level, max(row.level_error_gains_max_db, floor_db)),
        ):
            ax.annotate(
                str(row.gain_update_frames),
                (cpu, value),
                textcoords="offset points",
                xytext=(4, 4),
                fontsize=8,
                color=color,
            )
    ax_pos.axhline(TWO_POINT_THRESHOLD_CM, color="k", lw=1, label="two-point threshold")
    ax_pos.axhline(
        report.criteria["position_error_max_cm"], color="k", ls="--", lw=1, label="a tenth of it"
    )
    ax_level.axhline(report.criteria["level_error_max_db"], color="k", ls="--", lw=1)
    handles = [
        plt.Line2D([], [], marker="o", ls="", color="tab:blue", label="ramped, from gains"),
        plt.Line2D([], [], marker="o", ls="", color="tab:orange", label="held, from gains"),
        plt.Line2D([], [], marker="o", ls="", mfc="none", color="0.3", label="through twin"),
        plt.Line2D([], [], ls="", label=f"(errors of 0 drawn at {floor_cm:g})"),
    ]
    ax_pos.legend(handles=[*handles, *ax_pos.get_legend_handles_labels()[0]], fontsize=8)
    ax_pos.set_xlabel("CPU ms per second of audio (whole render)")
    ax_pos.set_ylabel("worst position error, cm")
    ax_pos.set_title("position error vs cost (labels: frames per gain update)")
    ax_level.set_xlabel("CPU ms per second of audio (whole render)")
    ax_level.set_ylabel("worst level error (gains) / variation (twin), dB")
    ax_level.set_title(f"level error vs cost; recommended: {report.recommended}")
    for ax in (ax_pos, ax_level):
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylim(bottom=float(np.float64(floor_cm) / 2))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
