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
    transients : TransientTable or None
        The clip's transients rendered at ``sample_rate_hz`` (the plan's, shared by its
        voices); None renders them here.
    """

    def __init__(
        self,
        clip: HapticClip,
        sample_rate_hz: int,
        *,
        loop: bool = False,
        transients: TransientTable | None = None,
    ) -> None:
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
        self._transients = (
            transients if transients is not None else TransientTable(clip, sample_rate_hz)
        )
        self._frames_per_loop = clip.duration_s * self._fs

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
        at_frames = np.arange(start_frame, start_frame + frames, dtype=np.float64)
        if self._loop:
            at_frames -= loops * self._frames_per_loop
        self._transients.add_to(signal, at_frames)
        return signal.astype(np.float32)

    def _phase_cycles(self, t_s: np.ndarray) -> np.ndarray:
        """Cycles of the continuous part at ``t_s`` (within one pass of the clip)."""
        k = np.clip(np.searchsorted(self._freq_t, t_s, side="right") - 1, 0, len(self._slope) - 1)
        dt_s = t_s - self._freq_t[k]
        return self._cycles[k] + _segment_cycles(self._freq_v[k], self._slope[k], dt_s)


class TransientTable:
    """A clip's transients rendered once, at the frames of one pass of the clip.

    Each transient ``i`` covers the frames ``n`` with ``0 <= n / fs - t_i < 3 / f_i``; the
    table holds their sum on the union of those frames, as runs of consecutive frames
    (a thousand transients apart: at most 60 ms each, 11.5 MB of float32 at 48 kHz). A block
    then reads its frames with one search and one gather, whatever the number of
    transients.

    Parameters
    ----------
    clip : HapticClip
        At most ``MAX_CLIP_TRANSIENTS`` transients (the schema's cap).
    sample_rate_hz : int
    """

    def __init__(self, clip: HapticClip, sample_rate_hz: int) -> None:
        fs = float(sample_rate_hz)
        t_s = np.array([t.t_s for t in clip.transients], dtype=np.float64)
        amp = np.array([t.amplitude for t in clip.transients], dtype=np.float64)
        freq_hz = clip_freq_hz(np.array([t.frequency for t in clip.transients]))
        length_s = TRANSIENT_CYCLES / freq_hz
        first = np.floor(t_s * fs).astype(np.int64)  # a frame either side of each span
        end = np.ceil((t_s + length_s) * fs).astype(np.int64) + 1
        order = np.argsort(first, kind="stable")
        reach = np.maximum.accumulate(end[order]) if order.size else end
        new_run = first[order] > np.r_[-1, reach[:-1]]  # runs: spans merged where they touch
        self.run_first = first[order][new_run]
        """First frame of each run, int64, increasing."""
        run_end = np.r_[reach[np.flatnonzero(new_run)[1:] - 1], reach[-1:]]
        self.run_frames = run_end - self.run_first
        """Frames of each run."""
        self.run_offset = np.cumsum(self.run_frames) - self.run_frames
        """Index in :attr:`values` of each run's first frame."""
        values = np.zeros(int(self.run_frames.sum()), dtype=np.float64)
        run_of = np.cumsum(new_run) - 1  # the run of each transient, in ``order``
        for k, i in enumerate(order):  # once per clip and rate, never per block
            frame = np.arange(first[i], end[i])
            local_s = frame / fs - t_s[i]
            inside = (local_s >= 0.0) & (local_s < length_s[i])
            u = local_s[inside]
            window = 0.5 - 0.5 * np.cos(2.0 * np.pi * u / length_s[i])
            at = self.run_offset[run_of[k]] + frame[inside] - self.run_first[run_of[k]]
            values[at] += amp[i] * window * np.sin(2.0 * np.pi * freq_hz[i] * u)
        self.values = values.astype(np.float32)
        """Sum of the transients on each frame of the runs, float32, shape (frames,)."""
        self._last = int(run_end[-1]) if run_end.size else -1

    @property
    def nbytes(self) -> int:
        return sum(
            a.nbytes for a in (self.values, self.run_first, self.run_offset, self.run_frames)
        )

    def add_to(self, signal: np.ndarray, at_frames: np.ndarray) -> None:
        """Add the transients at ``at_frames`` (frames of one pass of the clip, float64,
        increasing within a pass; between two frames: a line between them) into
        ``signal`` (same shape, float64)."""
        if self.values.size == 0 or at_frames.size == 0:
            return
        if at_frames.max() + 1.0 < self.run_first[0] or at_frames.min() >= self._last:
            return
        below = np.floor(at_frames)
        part = at_frames - below
        whole = below.astype(np.int64)
        signal += self._at(whole)
        if part.any():  # a loop of a fractional number of frames
            signal += part * (self._at(whole + 1) - self._at(whole))

    def _at(self, frames: np.ndarray) -> np.ndarray:
        run = np.searchsorted(self.run_first, frames, side="right") - 1
        safe = np.maximum(run, 0)
        offset = frames - self.run_first[safe]
        inside = (run >= 0) & (offset < self.run_frames[safe])
        index = np.where(inside, self.run_offset[safe] + offset, 0)
        return np.where(inside, self.values[index], 0.0)


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
