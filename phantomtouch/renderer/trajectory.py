"""Where the phantom point is and how strong it is at given times of a plan.

This is the control-rate part of the renderer: positions (from the plan's timelines),
the envelope (linear fades of eq. 1, amplitude modulation of eq. 2, keyframe
intensity) and the resulting per-channel gains.

Amplitude modulation may run at up to 1000 Hz, faster than any gain grid can follow
(a grid of 128 frames at 48 kHz samples it at 375 Hz and aliases it), so the block
renderer applies it per sample (:func:`modulation_at`) and takes its gains without it
(``control_gains(..., modulated=False)``).
"""

from __future__ import annotations

import numpy as np

from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.plan import Plan, Timeline


def _at(timeline: Timeline, tau_s: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    times = timeline.times_s
    points = np.empty((len(tau_s), 2))
    points[:, 0] = np.interp(tau_s, times, timeline.points_cm[:, 0])
    points[:, 1] = np.interp(tau_s, times, timeline.points_cm[:, 1])
    if timeline.intensity is None:
        return points, None
    return points, np.interp(tau_s, times, timeline.intensity)


def _stroke_time(plan: Plan, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stroke = np.floor(times_s / plan.stroke_s)
    np.maximum(stroke, 0.0, out=stroke)  # as np.clip, which costs more on a few values
    np.minimum(stroke, plan.strokes - 1, out=stroke)
    return stroke, times_s - stroke * plan.stroke_s


def _positions(
    plan: Plan, stroke: np.ndarray, tau_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """Points and keyframe intensity (None: 1 throughout) at stroke-local times."""
    points, intensity = _at(plan.forward, tau_s)
    if plan.backward is not None:
        back = stroke % 2 == 1
        if np.any(back):
            points[back], back_intensity = _at(plan.backward, tau_s[back])
            if intensity is not None and back_intensity is not None:  # both or neither
                intensity[back] = back_intensity
    return points, intensity


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
    points, intensity = _positions(plan, *_stroke_time(plan, times_s))
    return points, np.ones(len(times_s)) if intensity is None else intensity


def _unit_clamp(values: np.ndarray) -> np.ndarray:
    """Clamp ``values`` to [0, 1] in place (cheaper than np.clip on a few dozen values)."""
    np.maximum(values, 0.0, out=values)
    return np.minimum(values, 1.0, out=values)


def _modulation(
    plan: Plan, times_s: np.ndarray, tau_s: np.ndarray, dtype: type = np.float64
) -> np.ndarray | None:
    mod = plan.pattern.modulation
    if mod is None or mod.index <= 0:
        return None
    cycles = tau_s / plan.stroke_s if mod.freq_hz == "stroke" else times_s * float(mod.freq_hz)
    cycles -= np.floor(cycles)  # the phase wrapped in float64 keeps its precision for hours
    m = mod.index
    phase: np.ndarray = cycles.astype(dtype, copy=False)
    phase *= dtype(2.0 * np.pi)
    factor = np.cos(phase, out=phase)
    factor *= dtype(-m / 2.0)
    factor += dtype(1.0 - m / 2.0)
    return factor


def modulation_at(
    plan: Plan, times_s: np.ndarray, *, dtype: type = np.float64
) -> np.ndarray | None:
    """Amplitude modulation factor of eq. 2 at absolute pattern times.

    ``(1 - m/2) - (m/2) cos(2 pi f_m t)``, with ``f_m t`` replaced by the stroke-local
    time over the stroke's length for ``freq_hz="stroke"``. The phase is wrapped to one
    cycle in float64 whatever ``dtype``, so float32 (what the block renderer asks for:
    its cosine costs a twentieth) loses no precision over hours.

    Returns
    -------
    ndarray, shape (n,), ``dtype``, each in [0, 1], or None
        None when the pattern has no modulation (a factor of 1 throughout).
    """
    times_s = np.asarray(times_s, dtype=np.float64)
    _, tau = _stroke_time(plan, times_s)
    return _modulation(plan, times_s, tau, dtype)


def _envelope(
    plan: Plan, times_s: np.ndarray, tau_s: np.ndarray, *, modulated: bool = True
) -> np.ndarray:
    pattern = plan.pattern
    with np.errstate(over="ignore"):  # a fade of a few 1e-300 s overflows to inf, clipped to 1
        if pattern.fade_in_s > 0:
            env = _unit_clamp(tau_s / pattern.fade_in_s)
        else:
            env = np.ones(len(times_s))
        if pattern.fade_out_s > 0:
            fade = plan.stroke_s - tau_s
            fade /= pattern.fade_out_s
            env *= _unit_clamp(fade)
    if modulated:
        factor = _modulation(plan, times_s, tau_s)
        if factor is not None:
            env *= factor
    env[(times_s < 0) | (times_s >= plan.duration_s)] = 0.0
    return env


def envelope_at(plan: Plan, times_s: np.ndarray) -> np.ndarray:
    """Amplitude envelope at absolute pattern times, without keyframe intensity.

    Fades are linear (eq. 1) and restart with every stroke; amplitude modulation is
    eq. 2, with one period per stroke for ``freq_hz="stroke"``. Zero outside
    [0, duration_s].
    """
    times_s = np.asarray(times_s, dtype=np.float64)
    _, tau = _stroke_time(plan, times_s)
    return _envelope(plan, times_s, tau)


def control_gains(plan: Plan, times_s: np.ndarray, *, modulated: bool = True) -> np.ndarray:
    """Per-channel gains, envelope and amplitude included, at absolute pattern times.

    Parameters
    ----------
    plan : Plan
    times_s : ndarray, shape (n,), seconds from the pattern's start
    modulated : bool
        Include the amplitude modulation of eq. 2 (False: the caller applies
        :func:`modulation_at` itself, per sample).

    Returns
    -------
    ndarray, shape (n, channels), float64, each within [0, amplitude]
    """
    times_s = np.asarray(times_s, dtype=np.float64)
    stroke, tau = _stroke_time(plan, times_s)
    points, intensity = _positions(plan, stroke, tau)
    env = _envelope(plan, times_s, tau, modulated=modulated)
    if intensity is not None:
        env *= intensity
    env *= plan.amplitude
    pattern = plan.pattern
    gains, _ = gains_for_points(plan.geometry, points, law=pattern.law, mode=pattern.mode)
    gains *= env[:, None]
    return gains
