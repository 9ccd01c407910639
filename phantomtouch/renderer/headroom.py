"""How much of a pattern the safety ceiling will clip, known before it plays.

An accepted level can still drive a carrier's peaks past the ceiling: a sine's peak is
sqrt(2) times its RMS, Gaussian noise has no peak at all. Every frame's drive on channel
``c`` is ``carrier[n] * g_c[n]`` (gains with envelope, modulation, level and
calibration), and all channels share the carrier sample, so frame ``n`` clips on some
channel exactly when ``|carrier[n]| * max_c |g_c[n]| > ceiling``. The gains vary slowly,
the carrier fast and independently of them, so the fraction of clipped frames is the
mean over time of the carrier's exceedance ``P(|carrier| > ceiling / max_c |g_c|)``.

Exceedance is exact for a sine (``1 - (2/pi) arcsin(u)``) and taken from the noise loop
itself for noise and combined carriers. A modulation too fast for the gain grid is
averaged over its phase. The estimate is of the pattern played alone; the engine's
limiter acts on the sum of what plays at once.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from phantomtouch.renderer.carriers import NOISE_PERIOD_FRAMES, noise_loop
from phantomtouch.renderer.output import OutputStage
from phantomtouch.renderer.plan import Plan
from phantomtouch.renderer.trajectory import control_gains
from phantomtouch.schema.clip import ClipCarrier
from phantomtouch.schema.pattern import CombinedCarrier, NoiseCarrier, PatternCarrier, SineCarrier

_MAX_POINTS = 4096
"""Most control times the estimate evaluates the gains at."""
_NOISE_STEP = 16
"""Every this many frames of the noise loop form its amplitude distribution (65 536)."""
_PHASES = 64
"""Phases of a fast modulation averaged over."""


@lru_cache(maxsize=8)
def _sorted_magnitudes(carrier: PatternCarrier, sample_rate_hz: int) -> np.ndarray:
    """|carrier| over one noise period (every ``_NOISE_STEP``-th frame), ascending."""
    assert isinstance(carrier, NoiseCarrier | CombinedCarrier)
    loop = noise_loop(float(carrier.low_hz), float(carrier.high_hz), carrier.seed, sample_rate_hz)
    samples = loop[::_NOISE_STEP].astype(np.float64)  # a view of the loop, no copy of it
    if isinstance(carrier, CombinedCarrier):  # (sine + noise) / sqrt(2), as CombinedSource
        frames = np.arange(0, NOISE_PERIOD_FRAMES, _NOISE_STEP, dtype=np.float64)
        cycles = frames * (carrier.freq_hz / sample_rate_hz)
        samples = (samples + np.sin(2.0 * np.pi * (cycles - np.floor(cycles)))) / np.sqrt(2.0)
    magnitudes = np.sort(np.abs(samples))
    magnitudes.flags.writeable = False
    return magnitudes


def _exceedance(carrier: PatternCarrier, sample_rate_hz: int, threshold: np.ndarray) -> np.ndarray:
    """P(|carrier| > threshold) elementwise; 0 where the threshold is inf.

    A clip is a sine under an envelope of at most 1: the full sine's figure bounds it
    (its transients, a few ms each, aside).
    """
    if isinstance(carrier, SineCarrier | ClipCarrier):
        return 1.0 - (2.0 / np.pi) * np.arcsin(np.minimum(threshold, 1.0))
    magnitudes = _sorted_magnitudes(carrier, sample_rate_hz)
    above = len(magnitudes) - np.searchsorted(magnitudes, threshold, side="right")
    return np.asarray(above / len(magnitudes))


def clipped_fraction(plan: Plan) -> float:
    """Estimated fraction of the pattern's frames in which a channel reaches the ceiling.

    Returns
    -------
    float, in [0, 1]
        0 when no sample can reach the ceiling.
    """
    if plan.amplitude <= 0.0:
        return 0.0
    step = plan.device.gain_step_frames
    points = int(min(_MAX_POINTS, max(2, -(-plan.frames // step))))
    times_s = (np.arange(points) + 0.5) * (plan.duration_s / points)
    mod = plan.pattern.modulation
    fast = (
        mod is not None
        and mod.index > 0
        and mod.freq_hz != "stroke"
        and float(mod.freq_hz) > points / plan.duration_s / 4  # faster than the grid follows
    )
    gains = control_gains(plan, times_s, modulated=not fast)
    gains *= OutputStage.channel_gains(plan.device)
    loudest = np.abs(gains).max(axis=1)
    if fast and mod is not None:
        phase = 2.0 * np.pi * (np.arange(_PHASES) + 0.5) / _PHASES
        factor = (1.0 - mod.index / 2.0) - (mod.index / 2.0) * np.cos(phase)
        loudest = (loudest[:, None] * factor[None, :]).ravel()
    ceiling = float(plan.device.safety.ceiling)
    with np.errstate(divide="ignore"):
        threshold = np.where(loudest > 0.0, ceiling / loudest, np.inf)
    if not np.any(np.isfinite(threshold)):
        return 0.0
    return float(np.mean(_exceedance(plan.pattern.carrier, plan.sample_rate_hz, threshold)))
