"""Plan a pattern: resolve its path, timing (eq. 1), level and layout fit once.

A :class:`Plan` holds everything the block renderer needs; it is immutable and cheap to
share between an offline render and an engine voice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.carriers import NOISE_PERIOD_FRAMES
from phantomtouch.renderer.clip import TransientTable
from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.levels import amplitude_for_level, pattern_level_db
from phantomtouch.renderer.paths import ResolvedPath, resolve_path
from phantomtouch.schema import limits
from phantomtouch.schema.clip import ClipCarrier
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import NoiseCarrier, PatternCarrier, SineCarrier, TouchPattern

_NOISE_MAX_EDGE = 0.45
"""Highest noise band edge as a fraction of the sample rate."""


@dataclass(frozen=True, eq=False)
class Timeline:
    """Where the point is during one stroke, in stroke-local time.

    Positions between the times are linear; before the first time the point rests at the
    first point (fade-in), after the last at the last point (fade-out).

    Attributes
    ----------
    times_s : ndarray, shape (n,), non-decreasing
    points_cm : ndarray, shape (n, 2)
    intensity : ndarray, shape (n,) or None
        Keyframe intensities (factor on the amplitude), None for constant intensity.
    """

    times_s: np.ndarray
    points_cm: np.ndarray
    intensity: np.ndarray | None


@dataclass(frozen=True, eq=False)
class Plan:
    """A pattern resolved for one device and sample rate.

    Attributes
    ----------
    duration_s : float
        Whole pattern, eq. 1 per stroke times ``strokes``.
    frames : int
        ``round(duration_s * sample_rate_hz)``.
    stroke_s, motion_s : float
        One stroke with its fades, and its moving part alone.
    path_length_cm : float
        Length of the path of one stroke.
    speed_cm_s : float
        Constant speed of the motion (keyframe paths: mean speed); 0 for a still touch.
    level_db : float or None
        Acceleration level, dB re 1 µm/s² (None for silence).
    amplitude : float
        Voice amplitude, 1.0 = full-scale sine on a nominal channel.
    projected_points, max_projection_cm
        How many path vertices lay outside the layout and were projected, and how far.
    clipped_fraction : float
        Estimated fraction of frames the safety ceiling clips when the pattern plays
        alone (:mod:`~phantomtouch.renderer.headroom`); computed on first use, so it is
        not part of :meth:`summary`, which the engine calls when it schedules a plan.
    """

    pattern: TouchPattern
    device: DeviceProfile
    geometry: Geometry
    sample_rate_hz: int
    channels: int
    duration_s: float
    frames: int
    stroke_s: float
    motion_s: float
    strokes: int
    path_length_cm: float
    speed_cm_s: float
    level_db: float | None
    amplitude: float
    projected_points: int
    max_projection_cm: float
    forward: Timeline
    backward: Timeline | None

    @cached_property
    def clip_transients(self) -> TransientTable | None:
        """A clip carrier's transients rendered once at this plan's rate, shared by its
        voices (a :class:`~phantomtouch.renderer.clip.TransientTable`); None for other
        carriers. Computed on first use, outside the audio callback (a voice is made
        before it plays)."""
        carrier = self.pattern.carrier
        if not isinstance(carrier, ClipCarrier) or carrier.data is None:
            return None
        return TransientTable(carrier.data, self.sample_rate_hz)

    @cached_property
    def clipped_fraction(self) -> float:
        from phantomtouch.renderer.headroom import clipped_fraction  # it builds on Plan

        return clipped_fraction(self)

    def summary(self) -> dict[str, Any]:
        """The plan as plain JSON-ready values."""
        return {
            "duration_s": self.duration_s,
            "path_length_cm": self.path_length_cm,
            "speed_cm_s": self.speed_cm_s,
            "frames": self.frames,
            "channels": self.channels,
            "sample_rate_hz": self.sample_rate_hz,
            "strokes": self.strokes,
            "stroke_s": self.stroke_s,
            "motion_s": self.motion_s,
            "level_db": self.level_db,
            "amplitude": self.amplitude,
            "projected_points": self.projected_points,
            "max_projection_cm": self.max_projection_cm,
        }


def check_carrier_frequencies(carrier: PatternCarrier, sample_rate_hz: int) -> None:
    """Refuse a carrier the sample rate cannot play (patterns and live contacts alike).

    Raises
    ------
    ParameterError
        A sine at or above Nyquist, a noise band edge above ``0.45 * sample_rate_hz``,
        or a noise band narrower than ``limits.MIN_NOISE_LOOP_BINS`` steps of the loop.
    """
    nyquist = sample_rate_hz / 2.0
    if isinstance(carrier, ClipCarrier):
        check_clip(carrier)
        return
    if not isinstance(carrier, NoiseCarrier) and carrier.freq_hz >= nyquist:
        raise ParameterError(
            f"carrier.freq_hz={carrier.freq_hz!r} must be below the Nyquist frequency "
            f"{nyquist:g} Hz of sample_rate_hz={sample_rate_hz}"
        )
    if isinstance(carrier, SineCarrier):
        return
    if carrier.high_hz > _NOISE_MAX_EDGE * sample_rate_hz:
        raise ParameterError(
            f"carrier.high_hz={carrier.high_hz!r} must be <= {_NOISE_MAX_EDGE * sample_rate_hz:g} "
            f"Hz ({_NOISE_MAX_EDGE} x sample_rate_hz={sample_rate_hz})"
        )
    narrowest_hz = limits.MIN_NOISE_LOOP_BINS * sample_rate_hz / NOISE_PERIOD_FRAMES
    if carrier.high_hz - carrier.low_hz < narrowest_hz:
        raise ParameterError(
            f"carrier.low_hz={carrier.low_hz!r}, carrier.high_hz={carrier.high_hz!r}: this band "
            f"is too narrow for the noise loop of {NOISE_PERIOD_FRAMES} frames; at "
            f"sample_rate_hz={sample_rate_hz} it must be at least {narrowest_hz:.3g} Hz wide: "
            "widen the band"
        )


def _stroke_timing(pattern: TouchPattern, path: ResolvedPath) -> tuple[float, float]:
    """Motion time of one stroke and its speed (eq. 1)."""
    length = path.total_length_cm
    fades = pattern.fade_in_s + pattern.fade_out_s
    if path.times_s is not None:
        motion = float(path.times_s[-1])
        seg_time = np.diff(path.times_s)
        seg_len = np.diff(path.length_cm)
        if seg_len.size:
            seg_speed = seg_len / seg_time
            worst = int(np.argmax(seg_speed))
            if seg_speed[worst] > limits.MAX_SPEED_CM_S:
                raise ParameterError(
                    f"path.keyframes[{worst + 1}].t_s={float(path.times_s[worst + 1])!r}: the "
                    f"keyframe is reached at {seg_speed[worst]:.6g} cm/s; at most "
                    f"{limits.MAX_SPEED_CM_S:g} cm/s"
                )
        return motion, (length / motion if motion > 0 else 0.0)
    if pattern.speed_cm_s is not None:
        return length / pattern.speed_cm_s, (pattern.speed_cm_s if length > 0 else 0.0)
    assert pattern.duration_s is not None
    motion = pattern.duration_s / pattern.repeat - fades
    if motion < 0 or (length > 0 and motion <= 0):
        raise ParameterError(
            f"duration_s={pattern.duration_s!r} leaves no time to move: each of "
            f"{pattern.repeat} stroke(s) needs more than fade_in_s + fade_out_s = {fades:g} s"
        )
    speed = length / motion if motion > 0 else 0.0
    if speed > limits.MAX_SPEED_CM_S:
        raise ParameterError(
            f"duration_s={pattern.duration_s!r} needs {speed:.6g} cm/s along "
            f"{length:.6g} cm; at most {limits.MAX_SPEED_CM_S:g} cm/s"
        )
    return motion, speed


def _timelines(
    pattern: TouchPattern, path: ResolvedPath, motion_s: float
) -> tuple[Timeline, Timeline | None]:
    fade_in = pattern.fade_in_s
    if path.times_s is not None:
        local = path.times_s
    elif path.total_length_cm > 0:
        local = path.length_cm / path.total_length_cm * motion_s
    else:
        local = np.zeros(len(path.points_cm))
    forward = Timeline(fade_in + local, path.points_cm, path.intensity)
    if not (pattern.alternate and pattern.repeat > 1):
        return forward, None
    backward = Timeline(
        fade_in + (motion_s - local[::-1]),
        path.points_cm[::-1],
        None if path.intensity is None else path.intensity[::-1],
    )
    return forward, backward


def check_clip(carrier: ClipCarrier) -> None:
    """Refuse a clip carrier whose clip is not filled in. (Its band ends at
    ``CLIP_HIGH_HZ``, far below the Nyquist frequency of the lowest sample rate.)"""
    if carrier.data is None:
        raise ParameterError(
            f"carrier.clip={carrier.clip!r}: the clip is not in carrier.data; the service "
            "fills it in from its library (PUT /clips/{name}, phantomtouch import)"
        )


def plan(pattern: TouchPattern, device: DeviceProfile | None = None) -> Plan:
    """Resolve a pattern for a device: path, duration (eq. 1), level, layout fit.

    Parameters
    ----------
    pattern : TouchPattern
    device : DeviceProfile or None
        None: the paper's armband at 48 kHz.

    Returns
    -------
    Plan

    Raises
    ------
    ParameterError
        A frequency at or above Nyquist, a level above the device's maximum, a duration
        that leaves no time to move or exceeds the cap, or (with ``outside="error"``) a
        path point outside the layout. The message names the field and its value.
    """
    device = device or DeviceProfile.default()
    sample_rate_hz = device.sample_rate_hz
    check_carrier_frequencies(pattern.carrier, sample_rate_hz)
    geometry = Geometry.for_device(device)
    path = resolve_path(pattern.path)
    if len(path.points_cm) * (2 if pattern.alternate else 1) > limits.MAX_TIMELINE_POINTS:
        raise ParameterError(
            f"path: path has {len(path.points_cm)} points; at most "
            f"{limits.MAX_TIMELINE_POINTS} (half that with alternate=true)"
        )
    motion_s, speed_cm_s = _stroke_timing(pattern, path)
    stroke_s = pattern.fade_in_s + motion_s + pattern.fade_out_s
    duration_s = stroke_s * pattern.repeat
    if duration_s > limits.MAX_DURATION_S * (1 + 1e-12):
        raise ParameterError(
            f"duration_s={duration_s:.6g}: the pattern lasts {duration_s:.6g} s "
            f"({pattern.repeat} stroke(s) of {stroke_s:.6g} s); at most "
            f"{limits.MAX_DURATION_S:g} s: raise speed_cm_s or lower repeat"
        )
    frames = round(duration_s * sample_rate_hz)
    if frames < 1:
        raise ParameterError(
            f"duration_s={duration_s:.6g}: the pattern has zero duration (less than one frame "
            f"at {sample_rate_hz} Hz): give fades, a duration_s, or a path that moves"
        )
    _, distance = gains_for_points(geometry, path.points_cm, law=pattern.law, mode=pattern.mode)
    outside = np.flatnonzero(distance > 1e-9)
    if outside.size and pattern.outside == "error":
        i = int(outside[0])
        x, y = path.points_cm[i]
        raise ParameterError(
            f"outside='error': path point {i} at ({x:.6g}, {y:.6g}) cm lies {distance[i]:.3g} "
            f"cm outside the actuator layout of {device.name!r} "
            "(outside='error'; 'project' moves it onto it)"
        )
    forward, backward = _timelines(pattern, path, motion_s)
    level_db = pattern_level_db(pattern, device)
    return Plan(
        pattern=pattern,
        device=device,
        geometry=geometry,
        sample_rate_hz=sample_rate_hz,
        channels=device.channels,
        duration_s=duration_s,
        frames=frames,
        stroke_s=stroke_s,
        motion_s=motion_s,
        strokes=pattern.repeat,
        path_length_cm=path.total_length_cm,
        speed_cm_s=speed_cm_s,
        level_db=None if level_db == -math.inf else level_db,
        amplitude=amplitude_for_level(level_db, device),
        projected_points=int(outside.size),
        max_projection_cm=float(distance.max(initial=0.0)),
        forward=forward,
        backward=backward,
    )
