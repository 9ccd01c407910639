"""Carrier signals: sine, band-limited noise and their combination.

Every carrier has the RMS of a unit sine (1/sqrt(2)). The sine's phase is computed per
sample from the absolute frame index, wrapped in float64, so it neither drifts over
hours nor depends on how the signal is cut into blocks. Noise is seeded white noise
through a Butterworth band-pass in second-order sections (a high-order band-pass with a
low edge is unstable in (b, a) form), normalised by the filter's exact noise gain.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Protocol

import numpy as np
from scipy import signal

from phantomtouch.schema.pattern import Carrier, CombinedCarrier, NoiseCarrier, SineCarrier

NOISE_ORDER = 8
"""Butterworth order of each band edge (48 dB per octave)."""
_SINE_RMS = 1.0 / np.sqrt(2.0)


class CarrierSource(Protocol):
    """A mono carrier, rendered block after block."""

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        """Frames ``start_frame ..`` of the carrier, shape (frames,), float32.

        Stateful sources require consecutive calls (``start_frame`` continues the last).
        """
        ...


class SineSource:
    """``sin(2 pi f n / fs)`` from the absolute frame index ``n``."""

    def __init__(self, freq_hz: float, sample_rate_hz: int) -> None:
        self._cycles_per_frame = float(freq_hz) / float(sample_rate_hz)

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        cycles = np.arange(start_frame, start_frame + frames, dtype=np.float64)
        cycles *= self._cycles_per_frame
        cycles -= np.floor(cycles)
        cycles *= 2.0 * np.pi
        return np.sin(cycles.astype(np.float32))


NOISE_SETTLED = 1e-4
"""The noise preroll ends when less than this fraction of the band-pass impulse
response's energy is still to come: the output's variance is then steady to 0.0004 dB."""


def _butterworth(low_hz: float, high_hz: float, sample_rate_hz: int) -> np.ndarray:
    return signal.butter(
        NOISE_ORDER, [low_hz, high_hz], btype="bandpass", fs=sample_rate_hz, output="sos"
    )


def _slowest_pole_radius(sos: np.ndarray) -> float:
    return float(max(np.max(np.abs(np.roots(section[3:]))) for section in sos))


@lru_cache(maxsize=64)
def noise_settle_s(low_hz: float, high_hz: float, sample_rate_hz: int) -> float:
    """About how long the noise band-pass takes to settle, s.

    The time in which the energy of its slowest mode falls to ``NOISE_SETTLED``: about
    ``8 / bandwidth`` for a narrow band (7.7 s for 20-21 Hz), 0.1 s for 40-500 Hz, two
    minutes for 1-1.06 Hz.
    """
    radius = _slowest_pole_radius(_butterworth(low_hz, high_hz, sample_rate_hz))
    return float(np.log(NOISE_SETTLED) / (2.0 * np.log(radius)) / sample_rate_hz)


@lru_cache(maxsize=64)
def _band_pass_design(
    low_hz: float, high_hz: float, sample_rate_hz: int
) -> tuple[np.ndarray, float, int]:
    sos = _butterworth(low_hz, high_hz, sample_rate_hz)
    # the impulse response until its slowest mode has decayed by 200 dB
    decayed = int(np.ceil(np.log(1e-10) / np.log(_slowest_pole_radius(sos))))
    impulse = np.zeros(max(int(min(60.0, 50.0 / low_hz) * sample_rate_hz), decayed) + 1)
    impulse[0] = 1.0
    cumulative = np.cumsum(signal.sosfilt(sos, impulse) ** 2)
    energy = float(cumulative[-1])
    settle_frames = int(np.searchsorted(cumulative, (1.0 - NOISE_SETTLED) * energy))
    return sos, _SINE_RMS / np.sqrt(energy), settle_frames


def band_pass(low_hz: float, high_hz: float, sample_rate_hz: int) -> tuple[np.ndarray, float]:
    """Second-order sections of the noise band-pass and the factor to RMS 1/sqrt(2).

    The factor comes from the energy of the filter's impulse response (its exact noise
    gain for unit-variance white noise), summed until it has decayed.
    """
    sos, scale, _ = _band_pass_design(low_hz, high_hz, sample_rate_hz)
    return sos, scale


class NoiseSource:
    """Seeded Gaussian noise through a band-pass, RMS 1/sqrt(2), steady from frame 0."""

    def __init__(self, low_hz: float, high_hz: float, seed: int, sample_rate_hz: int) -> None:
        self._sos, self._scale, settle_frames = _band_pass_design(
            float(low_hz), float(high_hz), int(sample_rate_hz)
        )
        self._rng = np.random.Generator(np.random.PCG64(seed))
        self._state = np.zeros((self._sos.shape[0], 2))
        self._next_frame = 0
        preroll = max(int(min(1.0, 8.0 / low_hz) * sample_rate_hz), settle_frames)
        _, self._state = signal.sosfilt(
            self._sos, self._rng.standard_normal(preroll), zi=self._state
        )

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        if start_frame != self._next_frame:
            raise ValueError(
                f"noise is rendered in order: expected frame {self._next_frame}, got {start_frame}"
            )
        self._next_frame += frames
        out, self._state = signal.sosfilt(
            self._sos, self._rng.standard_normal(frames), zi=self._state
        )
        return (out * self._scale).astype(np.float32)


class CombinedSource:
    """``(sine + noise) / sqrt(2)``: equal-RMS parts, the sum at the sine's RMS."""

    def __init__(self, sine: SineSource, noise: NoiseSource) -> None:
        self._sine = sine
        self._noise = noise

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        mixed = self._sine.block(start_frame, frames) + self._noise.block(start_frame, frames)
        mixed *= np.float32(_SINE_RMS)
        return mixed


def make_source(carrier: Carrier, sample_rate_hz: int) -> CarrierSource:
    """The source for a carrier specification."""
    if isinstance(carrier, SineCarrier):
        return SineSource(carrier.freq_hz, sample_rate_hz)
    noise = NoiseSource(carrier.low_hz, carrier.high_hz, carrier.seed, sample_rate_hz)
    if isinstance(carrier, NoiseCarrier):
        return noise
    assert isinstance(carrier, CombinedCarrier)
    return CombinedSource(SineSource(carrier.freq_hz, sample_rate_hz), noise)
