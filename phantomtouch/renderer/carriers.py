"""Carrier signals: sine, band-limited noise and their combination.

Every carrier has the RMS of a unit sine (1/sqrt(2)), and every sample is a pure
function of its absolute frame index, so a carrier can be read in blocks of any size,
in any order, and the blocks concatenate to exactly the whole signal.

The sine's phase is computed per sample from the absolute frame index, wrapped in
float64, so it neither drifts over hours nor depends on how the signal is cut into
blocks.

Noise is a loop of ``NOISE_PERIOD_FRAMES`` frames (21.8 s at 48 kHz), computed once per
band, seed and sample rate: seeded white Gaussian noise whose spectrum is shaped by the
magnitude response of a Butterworth band-pass of order ``NOISE_ORDER`` per edge, then
scaled to RMS 1/sqrt(2) exactly. Shaping a whole period at once makes the loop seamless
(the filtering is circular) and the noise steady from its first frame, with no
pre-roll; reading it costs a copy. The period is a choice: longer than the paper's 12 s
stimuli, so each plays noise that does not repeat, and 4 MB of float32 per loop.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING, Protocol

import numpy as np

from phantomtouch.schema.clip import ClipCarrier
from phantomtouch.schema.pattern import CombinedCarrier, NoiseCarrier, PatternCarrier, SineCarrier

NOISE_ORDER = 8
"""Butterworth order of each band edge (48 dB per octave)."""
NOISE_PERIOD_FRAMES = 2**20
"""Length of the noise loop, frames (21.8 s at 48 kHz; 4 MB of float32)."""
if TYPE_CHECKING:
    from phantomtouch.renderer.clip import TransientTable

_NOISE_TABLES = 8
"""Noise loops kept at once (32 MB at most); another band or seed computes its own."""
_SINE_RMS = 1.0 / np.sqrt(2.0)


class CarrierSource(Protocol):
    """A mono carrier, a pure function of the absolute frame index."""

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        """Frames ``start_frame ..`` of the carrier, shape (frames,), float32, a new array."""
        ...


class SineSource:
    """``sin(2 pi f n / fs)`` from the absolute frame index ``n``."""

    def __init__(self, freq_hz: float, sample_rate_hz: int) -> None:
        self.cycles_per_frame = float(freq_hz) / float(sample_rate_hz)

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        cycles = np.arange(start_frame, start_frame + frames, dtype=np.float64)
        cycles *= self.cycles_per_frame
        cycles -= np.floor(cycles)
        cycles *= 2.0 * np.pi
        return np.sin(cycles.astype(np.float32))


def sine_blocks(
    start_frames: np.ndarray,
    cycles_per_frame: np.ndarray,
    index: np.ndarray,
    *,
    out: np.ndarray | None = None,
    scratch: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Many sines' blocks at once, each the samples :meth:`SineSource.block` gives, bit for
    bit (the same float64 phase, wrapped, then the float32 sine).

    Parameters
    ----------
    start_frames : ndarray, shape (n,), float64
        Each sine's first frame (whole numbers).
    cycles_per_frame : ndarray, shape (n,), float64
        Each sine's ``freq_hz / sample_rate_hz``.
    index : ndarray, shape (frames,), float64
        ``0, 1, ..., frames - 1``.
    out : ndarray, shape (n, frames), float32, optional
        Where the blocks go (a new array when None).
    scratch : two ndarrays, each shape (n, frames), float64, optional
        Room for the phases and their whole cycles: with ``out`` too, nothing is
        allocated (the audio callback's buffers).

    Returns
    -------
    ndarray, shape (n, frames), float32
        ``out`` when given.
    """
    phases, whole = (None, None) if scratch is None else scratch
    cycles = np.add(start_frames[:, None], index, out=phases)
    cycles *= cycles_per_frame[:, None]
    cycles -= np.floor(cycles, out=whole)
    cycles *= 2.0 * np.pi
    if out is None:
        return np.sin(cycles.astype(np.float32))
    np.copyto(out, cycles, casting="same_kind")
    return np.sin(out, out=out)


def band_pass_gain(
    low_hz: float, high_hz: float, sample_rate_hz: int, freqs_hz: np.ndarray
) -> np.ndarray:
    """Magnitude response of the noise band-pass at ``freqs_hz``.

    The digital Butterworth band-pass of order ``NOISE_ORDER`` per edge, as the bilinear
    transform with pre-warped edges makes it (``scipy.signal.butter(NOISE_ORDER, [low_hz,
    high_hz], "bandpass", fs=sample_rate_hz)``), in closed form: with the warped
    frequency ``w = 2 fs tan(pi f / fs)``, the gain is ``1 / sqrt(1 + r**(2 NOISE_ORDER))``,
    ``r = (w**2 - w_low w_high) / (w (w_high - w_low))``. -3 dB at both edges, 0 dB at
    their geometric mean.

    Parameters
    ----------
    low_hz, high_hz : float, ``0 < low_hz < high_hz < sample_rate_hz / 2``
    sample_rate_hz : int
    freqs_hz : ndarray, shape (n,), each in ``[0, sample_rate_hz / 2]``

    Returns
    -------
    ndarray, shape (n,), float64, each in [0, 1]
    """
    fs = float(sample_rate_hz)
    warped = 2.0 * fs * np.tan(np.pi * np.asarray(freqs_hz, dtype=np.float64) / fs)
    w_low, w_high = (2.0 * fs * np.tan(np.pi * edge / fs) for edge in (low_hz, high_hz))
    with np.errstate(divide="ignore", over="ignore"):  # 0 Hz and Nyquist: r is +-inf, gain 0
        ratio = (warped**2 - w_low * w_high) / (warped * (w_high - w_low))
        return 1.0 / np.sqrt(1.0 + ratio ** (2 * NOISE_ORDER))


@lru_cache(maxsize=_NOISE_TABLES)
def noise_loop(low_hz: float, high_hz: float, seed: int, sample_rate_hz: int) -> np.ndarray:
    """One period of the band-limited noise, read-only.

    White Gaussian noise from ``PCG64(seed)``, shaped in the frequency domain by
    :func:`band_pass_gain` and scaled so that the period's RMS is 1/sqrt(2).

    Returns
    -------
    ndarray, shape (NOISE_PERIOD_FRAMES,), float32
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    spectrum = np.fft.rfft(rng.standard_normal(NOISE_PERIOD_FRAMES))
    freqs_hz = np.fft.rfftfreq(NOISE_PERIOD_FRAMES, 1.0 / sample_rate_hz)
    spectrum *= band_pass_gain(low_hz, high_hz, sample_rate_hz, freqs_hz)
    noise = np.fft.irfft(spectrum, NOISE_PERIOD_FRAMES)
    noise *= _SINE_RMS / np.sqrt(np.mean(noise**2))
    loop = noise.astype(np.float32)
    loop.flags.writeable = False
    return loop


NoiseKey = tuple[float, float, int, int]
"""``(low_hz, high_hz, seed, sample_rate_hz)`` of a noise loop."""
_ADOPTED: dict[NoiseKey, np.ndarray] = {}
_REFUSE_BUILDING = False


def noise_key(low_hz: float, high_hz: float, seed: int, sample_rate_hz: int) -> NoiseKey:
    return (float(low_hz), float(high_hz), int(seed), int(sample_rate_hz))


def adopt_noise_loop(key: NoiseKey, loop: np.ndarray) -> None:
    """Use ``loop`` (computed by :func:`noise_loop` elsewhere, e.g. in another process)
    for ``key`` until :func:`forget_noise_loop`; the caller owns its lifetime."""
    _ADOPTED[key] = loop


def forget_noise_loop(key: NoiseKey) -> None:
    """Stop using the loop adopted for ``key`` (voices that read it keep it)."""
    _ADOPTED.pop(key, None)


def refuse_building() -> None:
    """From now on a noise source whose loop was not adopted raises LookupError instead
    of building it (an engine process's audio side: it never computes a loop)."""
    global _REFUSE_BUILDING
    _REFUSE_BUILDING = True


class NoiseSource:
    """Seeded band-limited Gaussian noise, RMS 1/sqrt(2), a loop of ``NOISE_PERIOD_FRAMES``.

    Frame ``n`` is frame ``n mod NOISE_PERIOD_FRAMES`` of :func:`noise_loop` (or of the
    same loop adopted with :func:`adopt_noise_loop`; after :func:`refuse_building`, only
    an adopted loop: else LookupError).
    """

    def __init__(self, low_hz: float, high_hz: float, seed: int, sample_rate_hz: int) -> None:
        key = noise_key(low_hz, high_hz, seed, sample_rate_hz)
        adopted = _ADOPTED.get(key)
        if adopted is None and _REFUSE_BUILDING:
            raise LookupError(f"noise loop {key} was not handed to this process")
        self._loop = adopted if adopted is not None else noise_loop(*key)

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        at = start_frame % NOISE_PERIOD_FRAMES
        if at + frames <= NOISE_PERIOD_FRAMES:
            return self._loop[at : at + frames].copy()
        return np.take(self._loop, np.arange(at, at + frames), mode="wrap")  # across the seam


class CombinedSource:
    """``(sine + noise) / sqrt(2)``: equal-RMS parts, the sum at the sine's RMS."""

    def __init__(self, sine: SineSource, noise: NoiseSource) -> None:
        self._sine = sine
        self._noise = noise

    def block(self, start_frame: int, frames: int) -> np.ndarray:
        mixed = self._sine.block(start_frame, frames) + self._noise.block(start_frame, frames)
        mixed *= np.float32(_SINE_RMS)
        return mixed


def make_source(
    carrier: PatternCarrier, sample_rate_hz: int, *, transients: TransientTable | None = None
) -> CarrierSource:
    """The source for a carrier specification (a clip's ``data`` must be filled in; its
    ``transients``, a plan's ``clip_transients``, are rendered here when not given)."""
    if isinstance(carrier, ClipCarrier):
        from phantomtouch.renderer.clip import ClipSource

        assert carrier.data is not None  # the plan refuses a clip without it
        return ClipSource(carrier.data, sample_rate_hz, loop=carrier.loop, transients=transients)
    if isinstance(carrier, SineCarrier):
        return SineSource(carrier.freq_hz, sample_rate_hz)
    noise = NoiseSource(carrier.low_hz, carrier.high_hz, carrier.seed, sample_rate_hz)
    if isinstance(carrier, NoiseCarrier):
        return noise
    assert isinstance(carrier, CombinedCarrier)
    return CombinedSource(SineSource(carrier.freq_hz, sample_rate_hz), noise)
