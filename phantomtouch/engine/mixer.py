"""The chain after the voices: wearer gains, safety limiter, output stage, meters. Real
time (the callback) unless a docstring says otherwise; construction is not."""

from __future__ import annotations

import math

import numpy as np

from phantomtouch.renderer import OutputStage
from phantomtouch.renderer.dc_blocker import DcBlocker
from phantomtouch.schema.device import DeviceProfile

THRESHOLD_RATIO = 0.9
"""The limiter acts on calibrated peaks above this fraction of the ceiling."""
ATTACK_S = 0.001
"""Time over which gain reduction sets in, s."""
RELEASE_S = 0.1
"""Time for the gain to recover from 0 to 1, s (linear)."""


class Limiter:
    """Smooth gain reduction of the summed signal.

    For each block: ``peak`` is the largest calibrated absolute sample. The target gain is
    1 when ``peak <= threshold`` else ``threshold / peak``; a falling gain reaches the
    target within ``ATTACK_S`` and holds it for the rest of the block, a rising gain
    climbs by at most ``frames / (RELEASE_S * sample_rate_hz)`` per block. At gain 1 and
    a peak within the threshold the block is not touched at all.

    Attributes
    ----------
    gain : float, 0 < gain <= 1
        Gain at the end of the last block.
    limited_blocks : int
        Blocks whose gain was below 1 anywhere.
    calibration : ndarray, shape (channels,), float32
        The calibration's gain per channel.
    """

    def __init__(self, device: DeviceProfile) -> None:
        self.threshold = THRESHOLD_RATIO * device.safety.ceiling
        self.calibration = OutputStage.channel_gains(device).astype(np.float32)
        self._attack_frames = max(1, round(ATTACK_S * device.sample_rate_hz))
        self._release_per_frame = 1.0 / (RELEASE_S * device.sample_rate_hz)
        self._curve = np.empty(device.block_frames, dtype=np.float32)
        self._index = np.arange(device.block_frames, dtype=np.float32)
        self.gain = 1.0
        self.limited_blocks = 0

    def process(self, block: np.ndarray, peak: float | None = None) -> None:
        """Limit ``block`` (frames, channels), float32, in place.

        ``peak`` is the block's largest calibrated absolute sample (NaN if any sample is
        NaN) when the caller has it already.
        """
        if peak is None:
            peak = float((np.abs(block).max(axis=0) * self.calibration).max())
        if not math.isfinite(peak):
            return  # the output stage mutes the block
        if peak <= self.threshold and self.gain >= 1.0:
            return
        frames = block.shape[0]
        target = 1.0 if peak <= self.threshold else self.threshold / peak
        new = min(target, self.gain + frames * self._release_per_frame, 1.0)
        curve = self._curve[:frames]
        ramp = min(self._attack_frames, frames) if new < self.gain else frames
        curve[ramp:] = new
        np.multiply(self._index[:ramp], np.float32((new - self.gain) / ramp), out=curve[:ramp])
        curve[:ramp] += np.float32(self.gain)
        block *= curve[:, None]
        self.gain = new
        self.limited_blocks += 1


WEARER_RAMP_S = 0.02
"""Time over which a change of the wearer's gains ramps in, s (960 frames at 48 kHz; two
cycles of the 100 Hz sine, so no step a wearer could feel as a click)."""


class WearerGains:
    """The wearer's per-channel gains, changed at a block boundary and ramped over
    ``WEARER_RAMP_S``.

    :meth:`set` leaves the new gains for the next block; :meth:`apply` scales a block:
    not at all while every gain is 1, by the gains while they hold, and from the block
    where they change by a line from the gains of that moment to the new ones, reached
    ``R = round(WEARER_RAMP_S * sample_rate_hz)`` frames later (frame ``k`` of the ramp
    gets ``old + (new - old) * (k + 1) / R``). A change during a ramp starts a new ramp
    from where the gains are, so no sequence of changes steps them.

    Attributes
    ----------
    gains : ndarray, shape (channels,), float32
        The gains in force at the end of the last block.
    """

    def __init__(self, device: DeviceProfile) -> None:
        self.gains = np.ones(device.channels, dtype=np.float32)
        self.ramp_frames = max(1, round(WEARER_RAMP_S * device.sample_rate_hz))
        self._pending: np.ndarray | None = None
        self._unity = True
        self._from = self.gains.copy()
        self._to = self.gains.copy()
        self._done = self.ramp_frames  # frames of the ramp applied so far
        self._step = np.arange(1, device.block_frames + 1, dtype=np.float32)[:, None]
        self._fraction = np.empty((device.block_frames, 1), dtype=np.float32)
        self._curve = np.empty((device.block_frames, device.channels), dtype=np.float32)

    def set(self, gains: np.ndarray) -> None:
        """Take ``gains`` (shape (channels,), float32, finite, > 0, checked by the host)
        from the next block on (real time, from an applier: any thread of the audio side)."""
        self._pending = gains

    @property
    def holds_unity(self) -> bool:
        """Every gain is 1, no ramp runs and none is pending: :meth:`apply` would leave a
        block as it is."""
        return self._pending is None and self._unity and self._done >= self.ramp_frames

    def apply(self, block: np.ndarray) -> bool:
        """Scale ``block`` (frames, channels), float32, in place; False when every gain
        is 1 (the block is left as it is)."""
        new, self._pending = self._pending, None
        if new is not None and not np.array_equal(new, self._to):
            self._from = self.gains.copy()
            self._to = new.astype(np.float32, copy=True)
            self._done = 0
        if self._done < self.ramp_frames:
            frames = block.shape[0]
            fraction = self._fraction[:frames]
            np.add(self._step[:frames], np.float32(self._done), out=fraction)
            fraction *= np.float32(1.0 / self.ramp_frames)
            np.minimum(fraction, np.float32(1.0), out=fraction)
            curve = self._curve[:frames]
            np.multiply(fraction, self._to - self._from, out=curve)
            curve += self._from
            self._done += frames
            if self._done >= self.ramp_frames:
                curve[frames - (self._done - self.ramp_frames) - 1 :] = self._to
                self.gains = self._to.copy()
                self._unity = bool(np.all(self.gains == 1.0))
            else:
                self.gains = curve[-1].copy()
            block *= curve
        elif not self._unity:
            block *= self.gains
        else:
            return False
        return True


class Mixer:
    """The chain after the voices, and the level meters.

    The voices' sum goes through the renderer's
    :class:`~phantomtouch.renderer.dc_blocker.DcBlocker` (transparent for everything the
    edge admits, within the ceiling), :class:`WearerGains`, the :class:`Limiter` (all channels
    alike, keeping the phantom's balance) and the renderer's
    :class:`~phantomtouch.renderer.OutputStage` (calibration, optional FIR, NaN/Inf muting,
    the hard clip at the ceiling): the stage of an offline render, so a pattern played
    alone arrives with the offline samples.

    Parameters
    ----------
    device : DeviceProfile
        Its safety ceiling, calibration, channels and block size.

    Attributes
    ----------
    levels : ndarray, shape (channels,), float32
        Peak absolute value per channel of the last output block.
    peak : float
        Largest absolute output sample since start.
    """

    def __init__(self, device: DeviceProfile) -> None:
        self.dc_blocker = DcBlocker(device.channels, device.sample_rate_hz, device.safety.ceiling)
        self.wearer = WearerGains(device)
        self.limiter = Limiter(device)
        self.stage = OutputStage(device)
        self.levels = np.zeros(device.channels, dtype=np.float32)
        self.peak = 0.0
        self._untouched_peak = min(self.limiter.threshold, float(self.stage.ceiling))
        self._calibrates = bool(np.any(self.limiter.calibration != 1.0))
        # channels first: a max along each row is far cheaper than one down the columns
        self._magnitude = np.empty((device.channels, device.block_frames), dtype=np.float32)

    def finish(self, block: np.ndarray) -> None:
        """Block DC, fit to the wearer, limit, calibrate and clip the mixed ``block`` in
        place, then meter it.

        Most blocks are finite with calibrated peaks within the limiter's threshold while
        its gain is 1: the limiter, the NaN guard and the clip leave them as they are. On a
        device without FIR such a block is only calibrated, and its levels are its
        calibrated peaks, found once. Every other block takes the whole chain, whose
        limiter uses the largest of those peaks. Both ways give the same samples and levels.
        The mix's peaks are found first: the DC blocker's bound takes them, and they stay
        the levels unless the blocker or the wearer's gains changed the block.

        While the wearer's gains are all 1 and hold, the limiter's gain is 1 and the device
        has no FIR, a plain block (finite, within the DC blocker's dead band and the
        limiter's threshold) takes all of that in one compiled pass
        (:meth:`DcBlocker.plain_pass <phantomtouch.renderer.dc_blocker.DcBlocker.plain_pass>`):
        the same samples, levels and state.
        """
        if self.wearer.holds_unity and self.limiter.gain >= 1.0 and not self.stage.has_fir:
            loudest = self.dc_blocker.plain_pass(
                block, self.levels, self.limiter.calibration, self._calibrates, self._untouched_peak
            )
            if loudest >= 0.0:
                if loudest > self.peak:
                    self.peak = loudest
                return
        levels = self._channel_peaks(block)
        changed = self.dc_blocker.process(block, float(levels.max()))
        if self.wearer.apply(block) or changed:
            levels = self._channel_peaks(block)
        levels *= self.limiter.calibration  # calibrated peaks: rounding keeps the order of |x|
        loudest = float(levels.max())  # NaN when any sample is NaN: the whole chain
        if loudest <= self._untouched_peak and self.limiter.gain >= 1.0 and not self.stage.has_fir:
            self.stage.calibrate(block)
        else:
            self.limiter.process(block, loudest)  # loudest is the limiter's peak
            self.stage.process(block)
            loudest = float(self._channel_peaks(block).max())
        if loudest > self.peak:
            self.peak = loudest

    def _channel_peaks(self, block: np.ndarray) -> np.ndarray:
        """Largest absolute sample per channel of ``block``, into :attr:`levels`."""
        magnitude = self._magnitude[:, : block.shape[0]]
        np.abs(block.T, out=magnitude)
        return np.maximum.reduce(
            magnitude, axis=1, out=self.levels
        )  # the ufunc: np.max adds a wrapper
