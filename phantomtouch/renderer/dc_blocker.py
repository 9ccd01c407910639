"""The DC blocker: a one-pole high-pass on the summed signal, per channel, with a dead band.

A voice-coil actuator held off centre by a constant or slowly moving drive heats its coil
and the skin feels nothing of it; the carriers start at ``limits.MIN_CARRIER_HZ`` (refused
below at the edge), so whatever lies far below that band is an error. Per channel the
blocker tracks the slow part of its input with a one-pole low-pass,

``m[n] = (1 - r) x[n] + r m[n-1]``, ``r = exp(-2 pi DC_BLOCK_HZ / sample_rate_hz)``,

and takes away what of it lies beyond a dead band of ``DC_DEAD_BAND`` times the ceiling:
``y[n] = x[n] - (m[n] - clip(m[n], -b, b))``.

- Beyond the dead band ``y = x - m + b sign(m)``: the one-pole high-pass ``x - m``,
  ``H(z) = r (1 - z**-1) / (1 - r z**-1)``, exactly 0 at 0 Hz, within 0.003 dB of 1 from
  20 Hz up; a constant offset decays to the dead band's edge with the time constant
  ``1 / (2 pi DC_BLOCK_HZ)`` (0.32 s).
- Within the band it changes nothing, bit for bit. Content at ``f`` Hz and peak ``p``
  moves ``m`` by at most ``2 p DC_BLOCK_HZ / f`` (the low-pass integrating half a cycle
  from rest), which for ``f >= MIN_CARRIER_HZ`` and ``p`` at most the ceiling is the dead
  band: content at 20 Hz and up (the sine and combined carriers the edge admits; clips and
  modulations whose content stays there), alone or mixed within the ceiling, passes
  untouched, so the engine still plays
  :func:`~phantomtouch.renderer.render`'s samples (the limiter is transparent below its
  threshold the same way). Content below 20 Hz (a noise band reaching below it, since
  noise bands start at ``limits.MIN_NOISE_BAND_HZ``; sidebands of a modulation deeper
  than its carrier; a clip envelope that rectifies its sine) may move it past the band:
  that is what it is there to take away.

The state is one float64 per channel, carried from block to block, so blocks of any size
give the samples of one whole run.

Most blocks cannot reach the band's edge, and for them the state is advanced in closed
form, without filtering a sample (a compiled loop, ``renderer/kernels.py``): over a block
of ``N`` frames with peak ``p``,
``|m[n]| <= |m[-1]| + (1 - r) N p`` for every ``n`` in it, so when that bound is within
the band the block is left as it is and the state becomes ``r**N m[-1] + w @ x`` with
``w[k] = (1 - r) r**(N - 1 - k)`` (one dot product per block). Only a block whose bound
passes the band is filtered sample by sample. Both ways the state is the same up to
float64 rounding, far below what a float32 sample shows.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from phantomtouch.schema import limits

DC_BLOCK_HZ = 0.5
"""Corner of the DC blocker's low-pass, Hz (time constant 0.32 s)."""
DC_DEAD_BAND = 2.0 * DC_BLOCK_HZ / limits.MIN_CARRIER_HZ
"""Dead band of the tracked offset, a fraction of the ceiling (0.05): the most a carrier
at ``MIN_CARRIER_HZ`` or above at full scale moves the low-pass."""


class DcBlocker:
    """One-pole high-pass per channel beyond a dead band (module docstring).

    Parameters
    ----------
    channels : int, >= 1
    sample_rate_hz : int, > 0
    ceiling : float, > 0
        The device's ceiling; the dead band is ``DC_DEAD_BAND * ceiling``.

    Attributes
    ----------
    blocked_blocks : int
        Blocks it changed.
    """

    def __init__(self, channels: int, sample_rate_hz: int, ceiling: float) -> None:
        self.pole = math.exp(-2.0 * math.pi * DC_BLOCK_HZ / sample_rate_hz)
        self.dead_band = DC_DEAD_BAND * float(ceiling)
        self.blocked_blocks = 0
        self._b = np.array([1.0 - self.pole])
        self._a = np.array([1.0, -self.pole])
        self._state = np.zeros((1, channels))
        self._closed: dict[int, tuple[np.ndarray, float, float]] = {}
        from phantomtouch.renderer import kernels  # numba: loaded with a blocker, not at import

        self._kernels = kernels

    def response(self, freq_hz: np.ndarray, sample_rate_hz: int) -> np.ndarray:
        """Magnitude of the high-pass beyond the dead band at ``freq_hz`` (shape (n,), Hz),
        shape (n,), float64."""
        z = np.exp(-2j * np.pi * np.asarray(freq_hz, dtype=np.float64) / sample_rate_hz)
        return np.abs(self.pole * (1.0 - z) / (1.0 - self.pole * z))

    def _closed_form(self, frames: int) -> tuple[np.ndarray, float, float]:
        """For a block of ``frames`` (made once per block size): ``r w`` (shape (frames,),
        float64), ``r**frames`` and ``(1 - r) frames``. The state kept is lfilter's, ``z =
        r m[-1]``, so it advances as ``z = r**N z + r w @ x``."""
        closed = self._closed.get(frames)
        if closed is None:
            powers = self.pole ** np.arange(frames, 0, -1, dtype=np.float64)
            closed = ((1.0 - self.pole) * powers, self.pole**frames, (1.0 - self.pole) * frames)
            self._closed[frames] = closed
        return closed

    def plain_pass(
        self,
        block: np.ndarray,
        levels: np.ndarray,
        calibration: np.ndarray,
        calibrate: bool,
        threshold: float,
    ) -> float:
        """The output chain's pass over ``block`` (frames, channels), float32, when it is
        plain, with this blocker's state (real time; :func:`kernels.plain_pass
        <phantomtouch.renderer.kernels.plain_pass>`): the state advanced in closed form,
        the block times ``calibration`` (shape (channels,), float32) in place when
        ``calibrate``, ``levels`` (shape (channels,), float32) its calibrated peaks, their
        largest returned. -1.0: the block is not plain (not finite, past the dead band's
        reach, or a calibrated peak over ``threshold``), nothing changed but ``levels``."""
        weights, decay, reach = self._closed_form(block.shape[0])
        return float(
            self._kernels.plain_pass(
                block,
                levels,
                self._state[0],
                weights,
                decay,
                reach,
                self.pole,
                self.dead_band,
                calibration,
                calibrate,
                threshold,
            )
        )

    def process(self, block: np.ndarray, peak: float | None = None) -> bool:
        """Block DC in ``block`` (frames, channels), float32, in place (real time: the
        callback; or the offline caller); True when it changed a sample. A block that
        cannot reach the band's edge is left as it is, the state advanced in closed form
        (module docstring); a NaN in the block resets the state (the output stage mutes
        that block). ``peak`` is the block's largest absolute sample (NaN when a sample
        is NaN) when the caller has it already."""
        frames = block.shape[0]
        if frames == 0:
            return False
        weights, decay, reach = self._closed_form(frames)
        if peak is None:
            peak = float(np.abs(block).max())
        state = self._state
        if float(np.abs(state).max()) / self.pole + reach * peak <= self.dead_band:  # most
            self._kernels.advance_dc(state[0], weights, decay, block, peak)
            return False
        slow, self._state = lfilter(self._b, self._a, block, axis=0, zi=state)
        if not math.isfinite(float(self._state.sum())):
            self._state.fill(0.0)
            return False
        if slow.max() <= self.dead_band and slow.min() >= -self.dead_band:
            return False
        excess = slow - np.clip(slow, -self.dead_band, self.dead_band)
        block -= excess.astype(np.float32)
        self.blocked_blocks += 1
        return True
