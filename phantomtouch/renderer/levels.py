"""Intensity: the paper's Table I levels and their conversion to drive amplitude.

Levels are RMS acceleration levels in dB re 1 µm/s². A voice's amplitude is relative to
the device's ``calibration.reference_level_db`` (the level of a full-scale sine), so a
sine of amplitude ``a`` gives ``reference_level_db + 20 log10(a)``; a noise carrier of
amplitude ``a`` has the same RMS as that sine and therefore the same level.
"""

from __future__ import annotations

import math

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import NoiseCarrier, TouchPattern

TABLE_I_DB: dict[str, dict[str, float]] = {
    "low": {"50": 128.0, "100": 128.0, "150": 131.0, "noise": 135.0},
    "high": {"50": 138.0, "100": 138.0, "150": 141.0, "noise": 145.0},
}
"""Kirchner et al. 2023, Table I: acceleration levels of the stimuli, dB re 1 µm/s²."""

_TABLE_FREQS_HZ = np.array([50.0, 100.0, 150.0])


def table_i_level_db(preset: str, carrier: object) -> float:
    """Table I level for ``preset`` ("low" or "high") and a carrier.

    A sine or combined carrier at a frequency between the table's columns gets the level
    interpolated linearly in log frequency, clamped outside 50-150 Hz; a combined carrier
    takes its sine's level, because its RMS is scaled to the sine's.
    """
    column = TABLE_I_DB[preset]
    if isinstance(carrier, NoiseCarrier):
        return column["noise"]
    freq_hz = float(getattr(carrier, "freq_hz", 100.0))
    levels = np.array([column["50"], column["100"], column["150"]])
    return float(np.interp(np.log2(freq_hz), np.log2(_TABLE_FREQS_HZ), levels))


def pattern_level_db(pattern: TouchPattern, device: DeviceProfile) -> float:
    """The acceleration level a pattern asks for, dB re 1 µm/s² (-inf for silence).

    Raises
    ------
    ParameterError
        The level exceeds the device's ``safety.max_level_db``.
    """
    max_db = device.safety.max_level_db
    if pattern.level_db is not None:
        level_db = pattern.level_db
        field = "level_db"
    elif isinstance(pattern.intensity, str):
        level_db = table_i_level_db(pattern.intensity, pattern.carrier)
        field = "intensity"
    else:
        rel = float(pattern.intensity)
        return max_db + 20.0 * math.log10(rel) if rel > 0.0 else -math.inf
    if level_db > max_db:
        raise ParameterError(
            f"{field}: it gives {level_db:g} dB re 1 µm/s²; the device allows at most "
            f"safety.max_level_db={max_db:g} dB"
        )
    return level_db


def amplitude_for_level(level_db: float, device: DeviceProfile) -> float:
    """Voice amplitude (1.0 = a full-scale sine on a nominal channel) for a level."""
    if level_db == -math.inf:
        return 0.0
    return float(10.0 ** ((level_db - device.calibration.reference_level_db) / 20.0))
