"""A haptic clip as a carrier: a sine whose amplitude and frequency follow the clip's
envelopes, plus its transients (docs/algorithms.md, sec. 11).

Every sample is a pure function of the frame index from the pattern's start, as for the
other carriers, so blocks of any size concatenate to the whole signal:

- amplitude ``a(t)``: the amplitude breakpoints joined by straight lines;
- frequency ``f(t) = CLIP_LOW_HZ * (CLIP_HIGH_HZ / CLIP_LOW_HZ) ** v(t)``, ``v(t)`` the
  frequency breakpoints joined by straight lines (0-1 spans the band logarithmically,
  as pitch is felt);
- phase: the integral of ``f``, in closed form on each segment of ``v`` (exponential in
  ``t`` there), accumulated in float64 cycles at the breakpoints and wrapped, so it is
  continuous however fast the frequency moves;
- a transient at ``t_i`` with amplitude ``A`` and frequency ``v_i``: three cycles of a
  sine at ``f(v_i)`` under a Hann window, peak ``A``, added to the continuous part.

A unit amplitude envelope gives a unit sine, RMS 1/sqrt(2), like every other carrier:
the pattern's intensity sets the level, the clip shapes it.
"""

from __future__ import annotations

import math

import numpy as np

from phantomtouch.schema.clip import HapticClip

CLIP_LOW_HZ = 50.0
"""Frequency of clip frequency 0: the paper's lowest carrier."""
CLIP_HIGH_HZ = 250.0
"""Frequency of clip frequency 1: near the skin's most sensitive frequency, within the
band the calibration equalises (40-500 Hz); 0.5 gives 112 Hz, near the paper's 100 Hz."""
TRANSIENT_CYCLES = 3
"""Length of a transient, in cycles of its frequency (60 ms at 50 Hz, 12 ms at 250 Hz)."""
_RATIO = CLIP_HIGH_HZ / CLIP_LOW_HZ
_LOG_RATIO = math.log(_RATIO)


def clip_freq_hz(value: np.ndarray | float) -> np.ndarray:
    """Frequency of clip frequency values 0-1, Hz."""
    return CLIP_LOW_HZ * _RATIO ** np.asarray(value, dtype=np.float64)


class ClipSource:
    """The signal of a clip from the pattern's start (frame 0).

    Parameters
    ----------
    clip : HapticClip
    sample_rate_hz : int
        Must exceed ``2 * CLIP_HIGH_HZ`` (checked by the plan).
    loop : bool
        Start again at ``clip.duration_s``; else silence after it.
    """

    def __init__(self, clip: HapticClip, sample_rate_hz: int, *, loop: bool = False) -> None:
        self._fs = float(sample_rate_hz)
        self._duration_s = clip.duration_s
        self._loop = loop
        self._amp_t = np.array([p.t_s for p in clip.amplitude])
        self._amp_v = np.array([p.value for p in clip.amplitude])
        times = np.array([p.t_s for p in clip.frequency])
        values = np.array([p.value for p in clip.frequency])
        # The frequency envelope spans [0, duration] with a breakpoint at each end.
        if times[0] > 0.0:
            times, values = np.r_[0.0, times], np.r_[values[0], values]
        if times[-1] < clip.duration_s:
            times, values = np.r_[times, clip.duration_s], np.r_[values, values[-1]]
        self._freq_t, self._freq_v = times, values
        span_s = np.diff(times)
        slope = np.divide(np.diff(values), span_s, out=np.zeros_like(span_s), where=span_s > 0)
        self._slope = slope
        self._cycles = np.r_[0.0, np.cumsum(_segment_cycles(values[:-1], slope, span_s))]
        self._cycles_per_loop = float(self._cycles[-1] % 1.0)
        self._tr_t = np.array([t.t_s for t in clip.transients])
        self._tr_a = np.array([t.amplitude for t in clip.transients])
        self._tr_f = clip_freq_hz(np.array([t.frequency for t in clip.transients]))
        self._tr_len_s = TRANSIENT_CYCLES / self._tr_f
        self._longest_s = float(self._tr_len_s.max(initial=0.0))

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        """Frames ``start_frame ..`` of the clip, shape (frames,), float32."""
        t_s = np.arange(start_frame, start_frame + frames, dtype=np.float64) / self._fs
        loops = np.zeros_like(t_s)
        if self._loop:
            loops = np.floor(t_s / self._duration_s)
            t_s = t_s - loops * self._duration_s
        amplitude = np.interp(t_s, self._amp_t, self._amp_v)
        if not self._loop:
            amplitude[t_s >= self._duration_s] = 0.0
        cycles = self._phase_cycles(np.minimum(t_s, self._duration_s))
        cycles += (loops * self._cycles_per_loop) % 1.0
        cycles -= np.floor(cycles)
        signal = amplitude * np.sin(2.0 * np.pi * cycles)
        self._add_transients(signal, t_s)
        return signal.astype(np.float32)

    def _phase_cycles(self, t_s: np.ndarray) -> np.ndarray:
        """Cycles of the continuous part at ``t_s`` (within one pass of the clip)."""
        k = np.clip(np.searchsorted(self._freq_t, t_s, side="right") - 1, 0, len(self._slope) - 1)
        dt_s = t_s - self._freq_t[k]
        return self._cycles[k] + _segment_cycles(self._freq_v[k], self._slope[k], dt_s)

    def _add_transients(self, signal: np.ndarray, t_s: np.ndarray) -> None:
        if self._tr_t.size == 0 or t_s.size == 0:
            return
        first = np.searchsorted(self._tr_t, t_s.min() - self._longest_s, side="left")
        last = np.searchsorted(self._tr_t, t_s.max(), side="right")
        for i in range(first, last):
            local = t_s - self._tr_t[i]
            inside = (local >= 0.0) & (local < self._tr_len_s[i])
            if not inside.any():
                continue
            u = local[inside]
            window = 0.5 - 0.5 * np.cos(2.0 * np.pi * u / self._tr_len_s[i])
            signal[inside] += self._tr_a[i] * window * np.sin(2.0 * np.pi * self._tr_f[i] * u)


def _segment_cycles(
    start_value: np.ndarray, slope_per_s: np.ndarray, dt_s: np.ndarray
) -> np.ndarray:
    """Cycles of ``f(v)`` over ``dt_s`` from ``v = start_value`` rising at ``slope_per_s``:
    ``f_low (r**(v + s dt) - r**v) / (s ln r)``, or ``f(v) dt`` where ``s`` is 0."""
    start_hz = clip_freq_hz(start_value)
    rise = slope_per_s * _LOG_RATIO * dt_s
    flat = np.abs(rise) < 1e-9
    safe = np.where(flat, 1.0, slope_per_s * _LOG_RATIO)
    return np.where(flat, start_hz * dt_s * (1.0 + rise / 2.0), start_hz * np.expm1(rise) / safe)
