"""Where the phantom point is and how strong it is at given times of a plan.

This is the control-rate part of the renderer: positions (from the plan's timelines),
the envelope (linear fades of eq. 1, amplitude modulation of eq. 2, keyframe
intensity) and the resulting per-channel gains.
"""

from __future__ import annotations

import numpy as np

from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.plan import Plan, Timeline


def _at(timeline: Timeline, tau_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    times = timeline.times_s
    points = np.stack(
        [
            np.interp(tau_s, times, timeline.points_cm[:, 0]),
            np.interp(tau_s, times, timeline.points_cm[:, 1]),
        ],
        axis=1,
    )
    if timeline.intensity is None:
        return points, np.ones(len(tau_s))
    return points, np.interp(tau_s, times, timeline.intensity)


def _stroke_time(plan: Plan, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stroke = np.clip(np.floor(times_s / plan.stroke_s), 0, plan.strokes - 1)
    return stroke, times_s - stroke * plan.stroke_s


def positions_at(plan: Plan, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phantom position and keyframe intensity at absolute pattern times.

    Parameters
    ----------
    plan : Plan
    times_s : ndarray, shape (n,), seconds from the pattern's start

    Returns
    -------
    points_cm : ndarray, shape (n, 2), as the path gives them (before projection)
    intensity : ndarray, shape (n,), keyframe intensity factor (1 without keyframes)
    """
    times_s = np.asarray(times_s, dtype=np.float64)
    stroke, tau = _stroke_time(plan, times_s)
    points, intensity = _at(plan.forward, tau)
    if plan.backward is not None:
        back = stroke % 2 == 1
        if np.any(back):
            points[back], intensity[back] = _at(plan.backward, tau[back])
    return points, intensity


def envelope_at(plan: Plan, times_s: np.ndarray) -> np.ndarray:
    """Amplitude envelope at absolute pattern times, without keyframe intensity.

    Fades are linear (eq. 1) and restart with every stroke; amplitude modulation is
    eq. 2, with one period per stroke for ``freq_hz="stroke"``. Zero outside
    [0, duration_s].
    """
    pattern = plan.pattern
    times_s = np.asarray(times_s, dtype=np.float64)
    _, tau = _stroke_time(plan, times_s)
    env = np.ones(len(times_s))
    with np.errstate(over="ignore"):  # a fade of a few 1e-300 s overflows to inf, clipped to 1
        if pattern.fade_in_s > 0:
            env *= np.clip(tau / pattern.fade_in_s, 0.0, 1.0)
        if pattern.fade_out_s > 0:
            env *= np.clip((plan.stroke_s - tau) / pattern.fade_out_s, 0.0, 1.0)
    mod = pattern.modulation
    if mod is not None and mod.index > 0:
        cycles = tau / plan.stroke_s if mod.freq_hz == "stroke" else times_s * float(mod.freq_hz)
        m = mod.index
        env *= (1.0 - m / 2.0) - (m / 2.0) * np.cos(2.0 * np.pi * cycles)
    env[(times_s < 0) | (times_s >= plan.duration_s)] = 0.0
    return env


def control_gains(plan: Plan, times_s: np.ndarray) -> np.ndarray:
    """Per-channel gains, envelope and amplitude included, at absolute pattern times.

    Returns
    -------
    ndarray, shape (n, channels), float64, each within [0, amplitude]
    """
    points, intensity = positions_at(plan, times_s)
    env = envelope_at(plan, times_s) * intensity * plan.amplitude
    pattern = plan.pattern
    gains, _ = gains_for_points(plan.geometry, points, law=pattern.law, mode=pattern.mode)
    gains *= env[:, None]
    return gains
