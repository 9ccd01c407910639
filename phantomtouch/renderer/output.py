"""The output stage after the mix: calibration, FIR correction, NaN guard, ceiling.

The FIR runs as a uniformly partitioned FFT convolution (:mod:`~phantomtouch.renderer.fir`).

Calibration is linear, so it is applied once to the summed signal. The engine puts a
smooth limiter before :meth:`OutputStage.process`; the hard clip here is the last line.
"""

from __future__ import annotations

import numpy as np

from phantomtouch.renderer.fir import PartitionedFir
from phantomtouch.schema.device import DeviceProfile


def frames_at_ceiling(block: np.ndarray, ceiling: float) -> int:
    """Frames of an output ``block`` (frames, channels) with a channel at the ceiling."""
    return int(np.count_nonzero((np.abs(block) >= np.float32(ceiling)).any(axis=1)))


class OutputStage:
    """Per-channel calibration gain and FIR, then the safety ceiling.

    Attributes
    ----------
    muted_blocks : int
        Blocks that carried NaN or Inf and were replaced by silence.
    """

    def __init__(self, device: DeviceProfile) -> None:
        cal = device.calibration
        self.ceiling = np.float32(device.safety.ceiling)
        self.muted_blocks = 0
        gains = self.channel_gains(device)
        self._gains = gains.astype(np.float32) if np.any(gains != 1.0) else None
        self._loudest_gain = float(gains.max()) * (1.0 + 1e-6)
        self._fir = None if cal.fir_taps is None else PartitionedFir(cal.fir_taps)

    @staticmethod
    def channel_gains(device: DeviceProfile) -> np.ndarray:
        """Calibration gain per output channel, shape (channels,), float64."""
        cal = device.calibration
        if cal.channel_level_db is None:
            return np.ones(device.channels)
        levels = np.array(cal.channel_level_db, dtype=np.float64)
        return np.asarray(10.0 ** ((cal.reference_level_db - levels) / 20.0))

    @property
    def has_fir(self) -> bool:
        """The device has FIR correction filters (they carry state from block to block)."""
        return self._fir is not None

    def calibrate(self, block: np.ndarray) -> None:
        """Apply the calibration gains alone to ``block`` in place, (frames, channels), float32.

        All :meth:`process` does to a block that is finite, within the ceiling once
        calibrated, on a device without FIR.
        """
        if self._gains is not None:
            block *= self._gains

    def process(self, block: np.ndarray, peak_bound: float | None = None) -> None:
        """Calibrate and limit ``block`` in place, shape (frames, channels), float32.

        ``peak_bound``, when given, is at least the block's largest absolute sample
        (:attr:`PatternRenderer.peak_bound <phantomtouch.renderer.voice.PatternRenderer>`):
        a finite bound that the calibration keeps within the ceiling, on a device without
        FIR, proves the block finite and unclipped, and it is only calibrated (the same
        samples, without a pass over them to look).
        """
        if (
            peak_bound is not None
            and self._fir is None
            and peak_bound * self._loudest_gain <= self.ceiling
        ):  # False for NaN
            self.calibrate(block)
            return
        self.calibrate(block)
        if block.size == 0:
            return
        if self._fir is not None:
            if not (np.isfinite(block.max()) and np.isfinite(block.min())):
                # muted before NaN or Inf enters the FIR's memory
                block[:] = 0.0
                self.muted_blocks += 1
            self._fir.process(block)
        high, low = block.max(), block.min()  # NaN or Inf anywhere shows in one of them
        if not (np.isfinite(high) and np.isfinite(low)):
            block[:] = 0.0
            self.muted_blocks += 1
        elif high > self.ceiling or low < -self.ceiling:
            np.clip(block, -self.ceiling, self.ceiling, out=block)
