"""The block renderer: one planned pattern, rendered block after block.

Both the offline render and the engine's pattern voices use :class:`PatternRenderer`,
so the two give the same samples. Each output sample is a pure function of its frame
index, so the blocks of any block size concatenate to exactly the whole render.

Gains are computed every ``device.gain_step_frames`` frames on a grid anchored at
frame 0, and ramped linearly between grid points (or held, ``gain_ramp=False``).
Amplitude modulation (eq. 2) is not on that grid: it multiplies the carrier per sample,
so it stays exact up to the highest modulation frequency a pattern may ask for.
"""

from __future__ import annotations

import numpy as np

from phantomtouch.renderer.carriers import CarrierSource, make_source
from phantomtouch.renderer.plan import Plan
from phantomtouch.renderer.trajectory import control_gains, modulation_at


def gain_block(
    carrier: np.ndarray,
    grid: np.ndarray,
    step_frames: int,
    offset: int,
    *,
    ramp: bool,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Carrier times per-frame gains interpolated from a grid of gains.

    The gain of frame ``j * step + r`` is ``(1 - r/step) * grid[j] + (r/step) * grid[j+1]``
    with ``ramp``, else ``grid[j]``. One batched matrix product per grid cell,
    ``[c (1 - f), c f] @ [grid[j]; grid[j+1]]``, computes carrier times gain for all
    channels at once, the same way for every cell whatever the block size (callers give
    every channel: the product's rounding depends on its width).

    Parameters
    ----------
    carrier : ndarray, shape (frames,), float32
    grid : ndarray, shape (points, channels), float32
        Gains at consecutive grid points; the first is at or before the first frame,
        and with ``ramp`` the last is at or after the frame after the last.
    step_frames : int, >= 1
    offset : int, ``0 <= offset < step_frames``
        First frame relative to the first grid point.
    ramp : bool
    out : ndarray, shape (frames, channels), float32, C-contiguous, optional
        Where to write the result; used as is when the block is grid aligned
        (``offset == 0``, ``frames`` a multiple of ``step_frames``).

    Returns
    -------
    ndarray, shape (frames, channels), float32
        ``out`` when it was written, else a new array.
    """
    frames = len(carrier)
    if step_frames == 1:
        return carrier[:, None] * grid[:frames]
    cells = (offset + frames + step_frames - 1) // step_frames
    padded = np.zeros(cells * step_frames, dtype=np.float32)
    padded[offset : offset + frames] = carrier
    by_cell = padded.reshape(cells, step_frames)
    channels = grid.shape[1]
    aligned = out is not None and offset == 0 and cells * step_frames == frames
    result = (
        out.reshape(cells, step_frames, channels)
        if aligned and out is not None
        else np.empty((cells, step_frames, channels), dtype=np.float32)
    )
    if ramp:
        fraction = np.arange(step_frames, dtype=np.float32) / np.float32(step_frames)
        weights = np.empty((cells, step_frames, 2), dtype=np.float32)
        np.multiply(by_cell, np.float32(1.0) - fraction, out=weights[:, :, 0])
        np.multiply(by_cell, fraction, out=weights[:, :, 1])
        row, col = grid.strides
        pairs = np.lib.stride_tricks.as_strided(
            grid, shape=(cells, 2, channels), strides=(row, row, col), writeable=False
        )
        np.matmul(weights, pairs, out=result)
    else:
        np.matmul(by_cell[:, :, None], grid[:cells, None, :], out=result)
    return result.reshape(-1, channels)[offset : offset + frames]


_ROUNDING_MARGIN = 1.0 + 1e-5
"""How far float32 products and the two-term sums of a ramp may exceed the exact bound
(a few units in the last place, 6e-8 each)."""


class PatternRenderer:
    """Renders one plan in consecutive blocks.

    Parameters
    ----------
    plan : Plan

    Attributes
    ----------
    position_frames : int
        First frame of the next block.
    active_span : tuple of int
        Channels ``lo:hi`` outside which the last block rendered is 0 (its gains are 0
        there); ``(0, 0)`` when it is silent.
    peak_bound : float
        At least the largest absolute sample of the last block rendered: its carrier's
        largest magnitude times its largest gain (a ramped gain lies between two grid
        points), widened by float32 rounding; NaN when either is not finite.

    Notes
    -----
    Frames past ``plan.frames`` are silent. A block whose non-zero gains span at most
    half the channels touches only that span; wider spans add all channels at once,
    which is faster than a strided add.
    """

    def __init__(self, plan: Plan) -> None:
        self.plan = plan
        self.position_frames = 0
        self.active_span = (0, 0)
        self.peak_bound = 0.0
        self._carrier: CarrierSource = make_source(
            plan.pattern.carrier, plan.sample_rate_hz, transients=plan.clip_transients
        )
        self._step = plan.device.gain_step_frames
        self._ramp = plan.device.gain_ramp
        self._frame_s = 1.0 / plan.sample_rate_hz
        mod = plan.pattern.modulation
        self._modulated = mod is not None and mod.index > 0

    @property
    def finished(self) -> bool:
        """True once every frame of the plan has been rendered."""
        return self.position_frames >= self.plan.frames

    @property
    def remaining_frames(self) -> int:
        return max(0, self.plan.frames - self.position_frames)

    def render_add(self, out: np.ndarray) -> None:
        """Add the next ``len(out)`` frames into ``out`` in place.

        Parameters
        ----------
        out : ndarray, shape (frames, channels), float32
            Mix buffer; frames past the pattern's end are left as they are.
        """
        self._render(out, overwrite=False)

    def render_into(self, out: np.ndarray) -> None:
        """Write the next ``len(out)`` frames into ``out``, replacing what it held.

        Same samples as :meth:`render_add` into zeros, with one pass less when the block
        is aligned to the gain grid. Frames past the pattern's end are set to 0.
        """
        self._render(out, overwrite=True)

    def _render(self, out: np.ndarray, *, overwrite: bool) -> None:
        frames = min(out.shape[0], self.remaining_frames)
        if overwrite:
            out[frames:] = 0.0
        self.active_span = (0, 0)
        self.peak_bound = 0.0
        if frames <= 0:
            return
        first = self.position_frames
        step = self._step
        j0 = first // step
        j1 = (first + frames - 1) // step + (1 if self._ramp and step > 1 else 0)
        grid_frames = np.arange(j0, j1 + 1, dtype=np.float64) * step
        grid = control_gains(self.plan, grid_frames * self._frame_s, modulated=False)
        active = np.flatnonzero(grid.any(axis=0))
        carrier = self._carrier.block(first, frames)
        if self._modulated:
            carrier *= self._modulation(first, frames)
        self.position_frames += frames
        if active.size == 0:
            if overwrite:
                out[:frames] = 0.0
            return
        lo, hi = int(active[0]), int(active[-1]) + 1
        self.active_span = (lo, hi)
        self.peak_bound = (
            float(np.abs(carrier).max()) * float(np.abs(grid).max()) * _ROUNDING_MARGIN
        )
        channels = out.shape[1]
        if overwrite or 2 * (hi - lo) > channels:
            lo, hi = 0, channels  # a contiguous add beats a strided one
        # Every channel's product, whatever the span: a matrix product rounds as the
        # kernel its width selects, and an add must give what render_into writes.
        grid32 = np.ascontiguousarray(grid, dtype=np.float32)
        offset = first - j0 * step
        if overwrite:
            dest = out[:frames]
            direct = dest if dest.flags.c_contiguous else None
            block = gain_block(carrier, grid32, step, offset, ramp=self._ramp, out=direct)
            if block is not direct:
                dest[...] = block
        else:
            out[:frames, lo:hi] += gain_block(carrier, grid32, step, offset, ramp=self._ramp)[
                :, lo:hi
            ]

    def _modulation(self, first: int, frames: int) -> np.ndarray:
        """Eq. 2's factor at frames ``first ..``, shape (frames,), float32."""
        times_s = np.arange(first, first + frames, dtype=np.float64) * self._frame_s
        factor = modulation_at(self.plan, times_s, dtype=np.float32)
        assert factor is not None  # only called for a modulated pattern
        return factor

    def render(self, frames: int) -> np.ndarray:
        """The next ``frames`` frames as a new array, shape (frames, channels), float32."""
        out = np.empty((frames, self.plan.channels), dtype=np.float32)
        self.render_into(out)
        return out
