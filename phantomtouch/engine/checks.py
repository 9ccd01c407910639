"""Argument checks shared by the engine's public methods: each returns the checked value
or raises ParameterError naming the argument, its value and what is allowed."""

from __future__ import annotations

import math

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.gains import LAWS

MAX_ID_CHARS = 64


def check_range(name: str, value: object, lo: float, hi: float, unit: str) -> float:
    """A finite number within [lo, hi], as a float."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ParameterError(f"{name}={value!r} must be a number within [{lo:g}, {hi:g}] {unit}")
    number = float(value)
    if not (math.isfinite(number) and lo <= number <= hi):
        raise ParameterError(f"{name}={value!r} must be finite and within [{lo:g}, {hi:g}] {unit}")
    return number


def check_int(name: str, value: object, lo: int, hi: int) -> int:
    """An integer within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not lo <= value <= hi:
        raise ParameterError(f"{name}={value!r} must be an integer within [{lo}, {hi}]")
    return int(value)


def check_seconds(name: str, value: object) -> float:
    """A finite number of seconds."""
    if isinstance(value, bool) or not (
        isinstance(value, int | float | np.floating) and math.isfinite(value)
    ):
        raise ParameterError(f"{name}={value!r} must be a finite number of seconds")
    return float(value)


def check_id(name: str, value: object) -> str:
    """A contact or owner id: a string of 1 to 64 characters."""
    if not isinstance(value, str) or not 1 <= len(value) <= MAX_ID_CHARS:
        raise ParameterError(f"{name}={value!r} must be a string of 1 to {MAX_ID_CHARS} characters")
    return value


def check_law(law: object) -> str:
    """An interpolation law of the renderer."""
    if not isinstance(law, str) or law not in LAWS:
        raise ParameterError(f"law={law!r} must be one of {sorted(LAWS)}")
    return law


def check_frame(name: str, value: object) -> int | None:
    """An optional frame number: None or an integer >= 0."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ParameterError(f"{name}={value!r} must be None or an integer frame >= 0")
    return int(value)


def check_ahead(frame: int, now_frames: int, sample_rate_hz: int, max_ahead_s: float) -> int:
    """A start frame at most ``max_ahead_s`` after ``now_frames``."""
    ahead_s = (frame - now_frames) / sample_rate_hz
    if ahead_s > max_ahead_s:
        raise ParameterError(
            f"start_frame={frame} is {ahead_s:.6g} s ahead of now_frames={now_frames}; "
            f"at most {max_ahead_s:g} s"
        )
    return frame


def check_channel_gains(name: str, value: object, channels: int) -> np.ndarray:
    """Per-channel linear gains: shape (channels,), finite and > 0, as a new float32 array."""
    try:
        gains = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name}={value!r} must be {channels} numbers") from exc
    if gains.shape != (channels,):
        raise ParameterError(f"{name} has shape {gains.shape}; it must be ({channels},)")
    bad = np.flatnonzero(~(np.isfinite(gains) & (gains > 0.0)))
    if bad.size:
        k = int(bad[0])
        raise ParameterError(f"{name}[{k}]={gains[k]!r} must be finite and > 0")
    return gains.astype(np.float32)
