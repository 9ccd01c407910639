"""The manifest of a rendered stimulus set: one row per stimulus, its factors as columns.

A researcher analysing responses needs each stimulus's factors (carrier, frequency,
intensity, amplitude modulation, speed, ...) without parsing file names. They are read from
the pattern itself and from its plan, and written twice: ``manifest.json`` (an object keyed
by stimulus name) and ``manifest.csv`` (the same rows, one column per field). Floats are
written with 10 significant digits, so that ``12.0`` is not ``11.999999999999998``.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import TouchPattern

SIGNIFICANT_DIGITS = 10
FACTOR_COLUMNS = (
    "carrier",
    "freq_hz",
    "low_hz",
    "high_hz",
    "intensity",
    "level_db",
    "am",
    "am_index",
    "am_freq_hz",
    "speed_cm_s",
    "path",
    "mode",
    "repeat",
    "alternate",
)
"""The pattern's factors; ``None`` (an empty CSV cell) where a factor does not apply."""
PLAN_COLUMNS = (
    "duration_s",
    "path_length_cm",
    "frames",
    "channels",
    "sample_rate_hz",
    "strokes",
    "stroke_s",
    "motion_s",
    "amplitude",
    "projected_points",
    "max_projection_cm",
)
COLUMNS = ("name", "file", *FACTOR_COLUMNS, *PLAN_COLUMNS)


def rounded(value: Any) -> Any:
    """``value`` with floats cut to :data:`SIGNIFICANT_DIGITS` significant digits."""
    if isinstance(value, float):
        return float(f"{value:.{SIGNIFICANT_DIGITS}g}")
    return value


def factors(pattern: TouchPattern, plan: Plan) -> dict[str, Any]:
    """The factors of one stimulus (see :data:`FACTOR_COLUMNS`)."""
    carrier = pattern.carrier
    modulation = pattern.modulation
    am = modulation is not None and modulation.index > 0.0
    return {
        "carrier": carrier.kind,
        "freq_hz": getattr(carrier, "freq_hz", None),
        "low_hz": getattr(carrier, "low_hz", None),
        "high_hz": getattr(carrier, "high_hz", None),
        "intensity": pattern.intensity if pattern.level_db is None else None,
        "level_db": plan.level_db,
        "am": am,
        "am_index": modulation.index if am and modulation is not None else 0.0,
        "am_freq_hz": modulation.freq_hz if am and modulation is not None else None,
        "speed_cm_s": plan.speed_cm_s,
        "path": pattern.path.kind,
        "mode": pattern.mode,
        "repeat": pattern.repeat,
        "alternate": pattern.alternate,
    }


def row(name: str, file_name: str, pattern: TouchPattern, plan: Plan) -> dict[str, Any]:
    """One manifest row: name, file, factors and plan, floats rounded."""
    summary = plan.summary()
    values = {
        "name": name,
        "file": file_name,
        **factors(pattern, plan),
        **{key: summary[key] for key in PLAN_COLUMNS},
    }
    return {key: rounded(values[key]) for key in COLUMNS}


def write_manifest(rows: Sequence[dict[str, Any]], out_dir: Path) -> tuple[Path, Path]:
    """Write ``manifest.json`` and ``manifest.csv`` into ``out_dir``; their paths."""
    json_path = out_dir / "manifest.json"
    by_name = {r["name"]: {k: v for k, v in r.items() if k != "name"} for r in rows}
    json_path.write_text(json.dumps(by_name, indent=2) + "\n", encoding="utf-8")
    csv_path = out_dir / "manifest.csv"
    with csv_path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows({k: "" if v is None else v for k, v in r.items()} for r in rows)
    return json_path, csv_path
