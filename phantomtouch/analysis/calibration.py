"""Calibrate an armband: measure each actuator, design its correction, verify the levels.

Per output channel, with an accelerometer on that channel's actuator:

1. **Excite**: band-limited noise (default 20-1000 Hz, the renderer's Butterworth noise)
   on that channel alone, recorded through a sound-card input.
2. **Estimate** the transfer function drive -> acceleration with Welch's H1 estimator,
   ``H1 = Pxy / Pxx`` (:func:`scipy.signal.csd` over :func:`scipy.signal.welch`), after
   removing the round-trip latency found by cross-correlation; the coherence tells how
   trustworthy each frequency is.
3. **Invert**: a regularised inverse by frequency sampling,
   ``C(f) = |H(f_ref)| T(f) |H(f)| / (|H(f)|^2 + beta)``, with Tikhonov regularisation
   ``beta = 1e-6 max |H|^2`` over the band (the correction boosts no frequency by more
   than 54 dB over the channel's strongest one, so a dead band is not driven into the
   ceiling, while a response 40 dB below the strongest is still met within 0.05 dB),
   and a target ``T`` that is flat over the corrected band (40-500 Hz,
   the paper's noise band) and rolls off around it (3rd-order Butterworth high-pass at
   25 Hz, 4th-order low-pass at 1 kHz), so nothing outside the band is boosted. Below
   the excited band ``|H|`` is continued with the ``f^2`` slope of a spring-mass
   actuator, above it flat. The FIR is the **minimum-phase** realisation of ``|C|``
   (folded real cepstrum), cut to ``taps`` with a half-Hann taper, and scaled to
   exactly 1 at ``f_ref``: it equalises the level of every frequency, adds almost no
   latency, and leaves the actuator's phase alone (the skin feels the envelope, not
   the phase).
4. **Store**: ``calibration.channel_level_db`` gets each channel's level of a
   full-scale sine at ``f_ref`` (the output stage scales each channel by
   ``10 ** ((reference_level_db - channel_level_db) / 20)``) and
   ``calibration.fir_taps`` the correction's shape.
5. **Verify**: sines at 50, 100 and 150 Hz and band noise rendered by the renderer with
   the calibrated profile (so the real output stage with its FIR is what is verified),
   played and recorded, their levels compared with the requested ones.

The measurement loop is a function ``play_record(drive) -> recorded``: the sound card
through :func:`sounddevice_loop`, or the digital twin through
:class:`~phantomtouch.analysis.twin.TwinLoop`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy import signal

from phantomtouch.analysis.twin import MICRO_M_S2, amplitude_m_s2
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.renderer.carriers import NoiseSource
from phantomtouch.renderer.render import render
from phantomtouch.schema import limits
from phantomtouch.schema.device import Calibration, DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

PlayRecord = Callable[[np.ndarray], np.ndarray]
"""Plays ``drive`` (frames, channels) float32 and returns the input, (frames,), in input
units (digital full scale = 1); the recording starts with the playback."""

BAND_HZ = (40.0, 500.0)
"""The corrected band: the paper's noise band, which holds its 50-150 Hz sines."""
VERIFY_FREQS_HZ = (50.0, 100.0, 150.0)
_TARGET_HIGH_PASS = (25.0, 3)
"""Target roll-off below the band: Butterworth high-pass (Hz, order)."""
_TARGET_LOW_PASS = (1000.0, 4)
"""Target roll-off above the band: Butterworth low-pass (Hz, order)."""
_REGULARISATION = 1e-6
_MIN_COHERENCE = 0.5
_LOG_FLOOR = 1e-4
"""Smallest |C| relative to its peak in the cepstrum (its zero at 0 Hz is not finite)."""


@dataclass(frozen=True)
class CalibrationSettings:
    """How to measure, design and verify.

    Attributes
    ----------
    excitation_hz : (low, high)
        Band of the excitation noise; must cover the corrected band.
    excitation_s : float
        Seconds of noise per channel.
    drive_rms : float, (0, 0.5]
        RMS of the excitation drive (full scale = 1).
    resolution_hz : float
        Frequency resolution of the Welch estimate (segment = sample rate / this).
    taps : int, 16 .. 4096
        Length of each correction FIR.
    reference_hz : float
        Frequency where ``channel_level_db`` is measured and the FIR's gain is 1.
    verify_level_db, verify_noise_level_db : float
        Requested levels, dB re 1 µm/s², of the verification sines and noise (the
        paper's Table I, low intensity: 128 dB for sines, 135 dB for noise).
    verify_s : float
        Length of each verification signal, fades included.
    tail_s : float
        Silence after every signal, so the recording holds the latency and decay.
    """

    excitation_hz: tuple[float, float] = (20.0, 1000.0)
    excitation_s: float = 8.0
    drive_rms: float = 0.1
    resolution_hz: float = 3.0
    taps: int = 4096
    reference_hz: float = 100.0
    verify_level_db: float = 128.0
    verify_noise_level_db: float = 135.0
    verify_s: float = 1.0
    tail_s: float = 0.3

    def __post_init__(self) -> None:
        low, high = self.excitation_hz
        if not (limits.MIN_NOISE_BAND_HZ <= low <= BAND_HZ[0] and high >= BAND_HZ[1]):
            raise ParameterError(
                f"excitation_hz={self.excitation_hz!r} must cover the corrected band "
                f"{BAND_HZ[0]:g}-{BAND_HZ[1]:g} Hz (low edge >= {limits.MIN_NOISE_BAND_HZ:g} Hz)"
            )
        if not 0.0 < self.drive_rms <= 0.5:
            raise ParameterError(f"drive_rms={self.drive_rms!r} must be within (0, 0.5]")
        if not 16 <= self.taps <= limits.MAX_FIR_TAPS:
            raise ParameterError(f"taps={self.taps!r} must be within [16, {limits.MAX_FIR_TAPS}]")
        for name in ("excitation_s", "resolution_hz", "verify_s"):
            if not getattr(self, name) > 0.0:
                raise ParameterError(f"{name}={getattr(self, name)!r} must be > 0")
        if not BAND_HZ[0] <= self.reference_hz <= BAND_HZ[1]:
            raise ParameterError(f"reference_hz={self.reference_hz!r} must lie within {BAND_HZ}")


@dataclass(frozen=True)
class Transfer:
    """A measured transfer function drive -> acceleration.

    Attributes
    ----------
    freqs_hz : ndarray, shape (n,)
    response : ndarray, shape (n,), complex
        m/s² (peak) per unit drive amplitude; NaN where the drive had no energy.
    coherence : ndarray, shape (n,)
    delay_frames : int
        Round-trip latency removed before the estimate.
    """

    freqs_hz: np.ndarray
    response: np.ndarray
    coherence: np.ndarray
    delay_frames: int

    def magnitude_at(self, freq_hz: float) -> float:
        """|H| at ``freq_hz``, interpolated linearly in dB."""
        valid = np.isfinite(self.response) & (np.abs(self.response) > 0)
        db = 20.0 * np.log10(np.abs(self.response[valid]))
        return float(10.0 ** (np.interp(freq_hz, self.freqs_hz[valid], db) / 20.0))


def estimate_delay(drive: np.ndarray, recorded: np.ndarray, *, max_frames: int) -> int:
    """Lag, 0 .. ``max_frames``, at which ``recorded`` best matches ``drive``."""
    corr = signal.correlate(recorded, drive, mode="full", method="fft")
    lags = signal.correlation_lags(len(recorded), len(drive), mode="full")
    keep = (lags >= 0) & (lags <= max_frames)
    return int(lags[keep][np.argmax(np.abs(corr[keep]))])


def estimate_transfer(
    drive: np.ndarray,
    recorded_m_s2: np.ndarray,
    *,
    sample_rate_hz: int,
    resolution_hz: float = 3.0,
    max_delay_s: float = 0.25,
) -> Transfer:
    """Welch H1 estimate of drive -> acceleration, latency removed.

    Parameters
    ----------
    drive : ndarray, shape (frames,)
    recorded_m_s2 : ndarray, shape (frames,), acceleration in m/s², starting with ``drive``
    sample_rate_hz : int
    resolution_hz : float
        Welch segment length is the next power of two of ``sample_rate_hz / resolution_hz``.
    max_delay_s : float
        Longest latency searched for.
    """
    drive = np.asarray(drive, dtype=np.float64)
    recorded = np.asarray(recorded_m_s2, dtype=np.float64)
    if drive.shape != recorded.shape or drive.ndim != 1:
        raise ParameterError(
            f"drive {drive.shape} and recorded {recorded.shape} must be 1D and equally long"
        )
    lag = estimate_delay(drive, recorded, max_frames=int(max_delay_s * sample_rate_hz))
    x, y = drive[: len(drive) - lag], recorded[lag:]
    nperseg = min(len(x), 1 << math.ceil(math.log2(sample_rate_hz / resolution_hz)))
    freqs, pxx = signal.welch(x, sample_rate_hz, nperseg=nperseg)
    _, pxy = signal.csd(x, y, sample_rate_hz, nperseg=nperseg)
    _, coherence = signal.coherence(x, y, sample_rate_hz, nperseg=nperseg)
    with np.errstate(divide="ignore", invalid="ignore"):
        response = np.where(pxx > 0.0, pxy / pxx, np.nan)
    return Transfer(freqs, response, np.nan_to_num(coherence), lag)


def target_response(freqs_hz: np.ndarray) -> np.ndarray:
    """|T|: flat over the band, Butterworth roll-offs around it."""
    f = np.asarray(freqs_hz, dtype=np.float64)
    (f_hp, n_hp), (f_lp, n_lp) = _TARGET_HIGH_PASS, _TARGET_LOW_PASS
    r = f / f_hp
    high_pass = r**n_hp / np.sqrt(1.0 + r ** (2 * n_hp))
    return np.asarray(high_pass / np.sqrt(1.0 + (f / f_lp) ** (2 * n_lp)))


def _minimum_phase(magnitude: np.ndarray) -> np.ndarray:
    """Minimum-phase impulse response of a magnitude on an rfft grid (folded cepstrum)."""
    n = 2 * (len(magnitude) - 1)
    floor = _LOG_FLOOR * float(np.max(magnitude))
    cepstrum = np.fft.irfft(np.log(np.maximum(magnitude, floor)), n)
    folded = np.zeros(n)
    folded[0] = cepstrum[0]
    folded[1 : n // 2] = 2.0 * cepstrum[1 : n // 2]
    folded[n // 2] = cepstrum[n // 2]
    return np.fft.irfft(np.exp(np.fft.rfft(folded)), n)


def inverse_fir(
    transfer: Transfer,
    *,
    sample_rate_hz: int,
    taps: int,
    reference_hz: float,
    measured_hz: tuple[float, float],
) -> np.ndarray:
    """The regularised minimum-phase inverse of ``transfer`` (see the module docstring).

    Returns
    -------
    ndarray, shape (taps,), float64
        Gain exactly 1 at ``reference_hz``.
    """
    n = 1 << max(16, math.ceil(math.log2(16 * taps)))
    grid = np.fft.rfftfreq(n, 1.0 / sample_rate_hz)
    low, high = measured_hz
    valid = (
        np.isfinite(transfer.response)
        & (transfer.freqs_hz >= low)
        & (transfer.freqs_hz <= high)
        & (np.abs(transfer.response) > 0)
    )
    if np.count_nonzero(valid) < 4:
        raise DeviceError(f"no usable response between {low:g} and {high:g} Hz")
    freqs, db = transfer.freqs_hz[valid], 20.0 * np.log10(np.abs(transfer.response[valid]))
    magnitude = 10.0 ** (np.interp(grid, freqs, db) / 20.0)
    below = grid < freqs[0]
    magnitude[below] *= (grid[below] / freqs[0]) ** 2  # spring-mass slope below the data
    band = (grid >= BAND_HZ[0]) & (grid <= BAND_HZ[1])
    beta = _REGULARISATION * float(np.max(magnitude[band] ** 2))
    h_ref = transfer.magnitude_at(reference_hz)
    correction = h_ref * target_response(grid) * magnitude / (magnitude**2 + beta)
    correction[0] = correction[1]
    impulse = _minimum_phase(correction)[:taps]
    fade = taps // 4
    if fade:
        impulse[-fade:] *= 0.5 + 0.5 * np.cos(np.pi * np.arange(1, fade + 1) / fade)
    at_ref = np.exp(-2j * np.pi * reference_hz / sample_rate_hz * np.arange(taps))
    return np.asarray(impulse / abs(np.dot(impulse, at_ref)))


def fir_gain(taps: np.ndarray, freqs_hz: np.ndarray, sample_rate_hz: int) -> np.ndarray:
    """|FIR response| at ``freqs_hz``."""
    _, response = signal.freqz(taps, 1.0, worN=np.asarray(freqs_hz, float), fs=sample_rate_hz)
    return np.abs(response)


def excitation(
    device: DeviceProfile, channel: int, settings: CalibrationSettings, *, seed: int = 0
) -> np.ndarray:
    """Band noise on ``channel`` alone, with 50 ms raised-cosine fades and a silent tail.

    Returns
    -------
    ndarray, shape (frames, channels), float32
    """
    rate = device.sample_rate_hz
    low, high = settings.excitation_hz
    if high > 0.45 * rate:
        raise ParameterError(f"excitation_hz high edge {high!r} must be <= {0.45 * rate:g} Hz")
    frames = round(settings.excitation_s * rate)
    noise = NoiseSource(low, high, seed, rate).block(0, frames).astype(np.float64)
    noise *= settings.drive_rms * math.sqrt(2.0)  # the source's RMS is 1/sqrt(2)
    fade = min(frames // 2, round(0.05 * rate))
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(fade) / fade)
    noise[:fade] *= ramp
    noise[frames - fade :] *= ramp[::-1]
    drive = np.zeros((frames + round(settings.tail_s * rate), device.channels), np.float32)
    drive[:frames, channel - 1] = noise
    return drive


@dataclass(frozen=True)
class ChannelMeasurement:
    """What the measurement of one channel found.

    ``level_db``: level of a full-scale sine at ``reference_hz``; ``spread_db``: max
    minus min of |H| over the band before correction; ``max_level_db``: highest sine
    level in the band this channel reaches before its drive hits the ceiling.
    """

    channel: int
    level_db: float
    spread_db: float
    coherence_min: float
    delay_frames: int
    fir_max_gain_db: float
    max_level_db: float


@dataclass(frozen=True)
class ChannelCheck:
    """Verification of one channel: measured minus requested level, dB."""

    channel: int
    sine_errors_db: dict[str, float]
    band_error_db: float

    @property
    def worst_db(self) -> float:
        return max(abs(e) for e in [*self.sine_errors_db.values(), self.band_error_db])


@dataclass
class CalibrationResult:
    """The calibrated profile, what was measured, and how well it verified."""

    profile: DeviceProfile
    measurements: list[ChannelMeasurement]
    checks: list[ChannelCheck] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """Plain values (the FIR taps are left to the profile file)."""
        return {
            "measurements": [asdict(m) for m in self.measurements],
            "checks": [{**asdict(c), "worst_db": c.worst_db} for c in self.checks],
            "channel_level_db": list(self.profile.calibration.channel_level_db or ()),
            "reference_level_db": self.profile.calibration.reference_level_db,
        }


def _channels(device: DeviceProfile, channels: Sequence[int] | None) -> list[int]:
    wired = sorted(a.channel for a in device.actuators)
    chosen = list(channels) if channels else wired
    for ch in chosen:
        if ch not in wired:
            raise ParameterError(f"channel={ch!r} drives no actuator; wired channels: {wired}")
    return chosen


def measure_channel(
    device: DeviceProfile,
    channel: int,
    play_record: PlayRecord,
    *,
    input_scale_m_s2: float,
    settings: CalibrationSettings,
) -> tuple[Transfer, np.ndarray, ChannelMeasurement]:
    """Excite one channel, estimate its response and design its correction."""
    rate = device.sample_rate_hz
    drive = excitation(device, channel, settings, seed=channel)
    recorded = np.asarray(play_record(drive), dtype=np.float64) * input_scale_m_s2
    if recorded.shape != (len(drive),):
        raise DeviceError(f"recording has shape {recorded.shape}; expected ({len(drive)},)")
    transfer = estimate_transfer(
        drive[:, channel - 1], recorded, sample_rate_hz=rate, resolution_hz=settings.resolution_hz
    )
    band = (transfer.freqs_hz >= BAND_HZ[0]) & (transfer.freqs_hz <= BAND_HZ[1])
    coherence_min = float(np.min(transfer.coherence[band]))
    if not coherence_min >= _MIN_COHERENCE:
        raise DeviceError(
            f"channel {channel}: coherence {coherence_min:.2f} between {BAND_HZ[0]:g} and "
            f"{BAND_HZ[1]:g} Hz (at least {_MIN_COHERENCE} needed): is the accelerometer on "
            f"actuator {channel} and connected to the input?"
        )
    taps = inverse_fir(
        transfer,
        sample_rate_hz=rate,
        taps=settings.taps,
        reference_hz=settings.reference_hz,
        measured_hz=settings.excitation_hz,
    )
    magnitude_db = 20.0 * np.log10(np.abs(transfer.response[band]))
    level_db = float(20.0 * np.log10(transfer.magnitude_at(settings.reference_hz) / math.sqrt(2)))
    level_db -= 20.0 * math.log10(MICRO_M_S2)
    if not limits.MIN_LEVEL_DB <= level_db <= limits.MAX_LEVEL_DB:
        raise DeviceError(
            f"channel {channel}: a full-scale sine measures {level_db:.1f} dB re 1 µm/s², "
            f"outside [{limits.MIN_LEVEL_DB:g}, {limits.MAX_LEVEL_DB:g}]: check the sensitivity"
        )
    gain_db = 20.0 * np.log10(fir_gain(taps, transfer.freqs_hz[band], rate))
    reference_db = device.calibration.reference_level_db
    drive_db = reference_db - level_db + float(np.max(gain_db))  # per unit voice amplitude
    measurement = ChannelMeasurement(
        channel=channel,
        level_db=level_db,
        spread_db=float(np.ptp(magnitude_db)),
        coherence_min=coherence_min,
        delay_frames=transfer.delay_frames,
        fir_max_gain_db=float(np.max(gain_db)),
        max_level_db=reference_db + 20.0 * math.log10(device.safety.ceiling) - drive_db,
    )
    return transfer, taps, measurement


def calibrated_profile(
    device: DeviceProfile, levels_db: dict[int, float], taps: dict[int, np.ndarray]
) -> DeviceProfile:
    """``device`` with the measured channels' levels and FIRs; other channels keep theirs
    (nominal level and a unit FIR if they had none)."""
    cal = device.calibration
    reference = cal.reference_level_db
    old_levels = cal.channel_level_db or (reference,) * device.channels
    old_taps = cal.fir_taps or ((1.0,),) * device.channels
    channel_level_db = tuple(
        float(levels_db.get(ch, old_levels[ch - 1])) for ch in range(1, device.channels + 1)
    )
    fir_taps = tuple(
        tuple(float(v) for v in taps[ch]) if ch in taps else tuple(old_taps[ch - 1])
        for ch in range(1, device.channels + 1)
    )
    calibration = Calibration(
        reference_level_db=reference, channel_level_db=channel_level_db, fir_taps=fir_taps
    )
    return DeviceProfile.model_validate({**device.model_dump(), "calibration": calibration})


def _point_pattern(
    x_cm: float, y_cm: float, carrier: dict[str, Any], level_db: float, duration_s: float
) -> TouchPattern:
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[x_cm, y_cm]]},
            "duration_s": duration_s,
            "fade_in_s": 0.05,
            "fade_out_s": 0.05,
            "carrier": carrier,
            "level_db": level_db,
        }
    )


def _lock_in_rms(x: np.ndarray, freq_hz: float, sample_rate_hz: int) -> float:
    """RMS of the component of ``x`` at ``freq_hz`` (over whole periods)."""
    periods = math.floor(len(x) * freq_hz / sample_rate_hz)
    n = max(1, round(periods * sample_rate_hz / freq_hz))
    phase = 2.0 * np.pi * freq_hz * np.arange(n) / sample_rate_hz
    c = 2.0 * np.mean(x[:n] * np.cos(phase))
    s = 2.0 * np.mean(x[:n] * np.sin(phase))
    return math.hypot(c, s) / math.sqrt(2.0)


def _band_power(x: np.ndarray, sample_rate_hz: int, nperseg: int) -> float:
    freqs, psd = signal.welch(x, sample_rate_hz, nperseg=min(nperseg, len(x)))
    band = (freqs >= BAND_HZ[0]) & (freqs <= BAND_HZ[1])
    return float(np.sum(psd[band]) * (freqs[1] - freqs[0]))


def verify(
    profile: DeviceProfile,
    play_record: PlayRecord,
    *,
    input_scale_m_s2: float,
    channels: Sequence[int] | None = None,
    settings: CalibrationSettings | None = None,
    before_channel: Callable[[int], None] | None = None,
) -> list[ChannelCheck]:
    """Play sines and band noise rendered with ``profile`` and compare the levels.

    Each signal is a still touch on the channel's actuator rendered by
    :func:`~phantomtouch.render` (output stage, calibration gain and FIR included); the
    recorded level over its steady middle is compared with the requested level: the
    sines by their component at the carrier frequency, the noise by its power between
    40 and 500 Hz against that of the requested acceleration (the uncalibrated render
    scaled by the reference level).
    """
    settings = settings or CalibrationSettings()
    rate = profile.sample_rate_hz
    nominal = profile.model_copy(
        update={
            "calibration": Calibration(reference_level_db=profile.calibration.reference_level_db)
        }
    )
    full_scale_m_s2 = amplitude_m_s2(profile.calibration.reference_level_db)
    tail = np.zeros((round(settings.tail_s * rate), profile.channels), np.float32)
    skip = round(0.25 * rate)  # fade-in, FIR and actuator transients
    nperseg = 1 << math.ceil(math.log2(rate / 10.0))
    checks = []
    for ch in _channels(profile, channels):
        if before_channel is not None:
            before_channel(ch)
        actuator = next(a for a in profile.actuators if a.channel == ch)

        def steady(pattern: TouchPattern, ch: int = ch) -> tuple[np.ndarray, np.ndarray]:
            drive = render(pattern, profile)
            recorded = np.asarray(play_record(np.concatenate([drive, tail])), dtype=np.float64)
            recorded *= input_scale_m_s2
            lag = estimate_delay(
                drive[:, ch - 1].astype(np.float64), recorded[: len(drive)], max_frames=len(tail)
            )
            stop = len(drive) - round(0.05 * rate)
            return recorded[lag + skip : lag + stop], np.arange(skip, stop)

        errors = {}
        for freq in VERIFY_FREQS_HZ:
            carrier = {"kind": "sine", "freq_hz": freq}
            pattern = _point_pattern(
                actuator.x_cm, actuator.y_cm, carrier, settings.verify_level_db, settings.verify_s
            )
            part, _ = steady(pattern)
            rms = _lock_in_rms(part, freq, rate)
            errors[f"{freq:g}"] = 20.0 * math.log10(rms / MICRO_M_S2) - settings.verify_level_db
        noise = {"kind": "noise", "low_hz": BAND_HZ[0], "high_hz": BAND_HZ[1], "seed": ch}
        pattern = _point_pattern(
            actuator.x_cm,
            actuator.y_cm,
            noise,
            settings.verify_noise_level_db,
            max(settings.verify_s, 2.0),
        )
        part, frames = steady(pattern)
        requested = render(pattern, nominal)[frames, ch - 1].astype(np.float64) * full_scale_m_s2
        band_error = 10.0 * math.log10(
            _band_power(part, rate, nperseg) / _band_power(requested, rate, nperseg)
        )
        checks.append(ChannelCheck(channel=ch, sine_errors_db=errors, band_error_db=band_error))
    return checks


def calibrate(
    device: DeviceProfile,
    play_record: PlayRecord,
    *,
    input_scale_m_s2: float,
    channels: Sequence[int] | None = None,
    settings: CalibrationSettings | None = None,
    before_channel: Callable[[int], None] | None = None,
    check: bool = True,
) -> CalibrationResult:
    """Measure, correct and (with ``check``) verify the channels of ``device``.

    Parameters
    ----------
    device : DeviceProfile
        The armband; its ``calibration.reference_level_db`` is kept.
    play_record : PlayRecord
        The measurement loop (:func:`sounddevice_loop` or a
        :class:`~phantomtouch.analysis.twin.TwinLoop`).
    input_scale_m_s2 : float, > 0
        Acceleration, m/s², that reads as 1.0 on the input (see :func:`input_scale`).
    channels : sequence of int or None
        Output channels to calibrate (1-based); None: every wired channel.
    settings : CalibrationSettings or None
    before_channel : callable(channel) or None
        Called before each channel is measured (and verified), e.g. to ask the user to
        move the accelerometer onto that actuator.
    check : bool
        Also verify the calibrated profile.

    Raises
    ------
    DeviceError
        A channel gave no coherent response or an implausible level.
    """
    settings = settings or CalibrationSettings()
    if not input_scale_m_s2 > 0.0:
        raise ParameterError(f"input_scale_m_s2={input_scale_m_s2!r} must be > 0")
    chosen = _channels(device, channels)
    levels: dict[int, float] = {}
    taps: dict[int, np.ndarray] = {}
    measurements = []
    for ch in chosen:
        if before_channel is not None:
            before_channel(ch)
        _, taps[ch], measured = measure_channel(
            device, ch, play_record, input_scale_m_s2=input_scale_m_s2, settings=settings
        )
        levels[ch] = measured.level_db
        measurements.append(measured)
    profile = calibrated_profile(device, levels, taps)
    result = CalibrationResult(profile=profile, measurements=measurements)
    if check:
        result.checks = verify(
            profile,
            play_record,
            input_scale_m_s2=input_scale_m_s2,
            channels=chosen,
            settings=settings,
            before_channel=before_channel,
        )
    return result


def input_scale(
    *,
    sensitivity_v_per_m_s2: float | None = None,
    input_full_scale_v: float | None = None,
    input_reference_level_db: float | None = None,
) -> float:
    """m/s² per unit of input from the sensor's sensitivity and the input's full scale
    (both given), or from the level of a full-scale sine at the input (dB re 1 µm/s²)."""
    if input_reference_level_db is not None:
        if sensitivity_v_per_m_s2 is not None or input_full_scale_v is not None:
            raise ParameterError(
                "give input_reference_level_db, or sensitivity_v_per_m_s2 with "
                "input_full_scale_v, not both"
            )
        return amplitude_m_s2(input_reference_level_db)
    if sensitivity_v_per_m_s2 is None or input_full_scale_v is None:
        raise ParameterError(
            "give sensitivity_v_per_m_s2 and input_full_scale_v, or input_reference_level_db"
        )
    for name, value in (
        ("sensitivity_v_per_m_s2", sensitivity_v_per_m_s2),
        ("input_full_scale_v", input_full_scale_v),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ParameterError(f"{name}={value!r} must be finite and > 0")
    return input_full_scale_v / sensitivity_v_per_m_s2


def sounddevice_loop(
    *,
    sample_rate_hz: int,
    output_device: int | str | None,
    input_device: int | str | None,
    input_channel: int,
) -> PlayRecord:
    """A :data:`PlayRecord` through the sound card (needs the ``audio`` extra).

    Raises
    ------
    DeviceError
        sounddevice (or PortAudio) is missing, or the sound card refuses.
    """
    try:
        import sounddevice as sd
    except (ImportError, OSError) as exc:
        raise DeviceError(
            f"calibrate needs sounddevice and PortAudio: pip install 'phantomtouch[audio]' ({exc})"
        ) from exc
    if input_channel < 1:
        raise ParameterError(f"input_channel={input_channel!r} must be >= 1")

    def play_record(drive: np.ndarray) -> np.ndarray:
        try:
            recorded = sd.playrec(
                np.ascontiguousarray(drive, dtype=np.float32),
                samplerate=sample_rate_hz,
                input_mapping=[input_channel],
                device=(input_device, output_device),
                dtype="float32",
                blocking=True,
            )
        except (sd.PortAudioError, ValueError) as exc:
            raise DeviceError(f"sound card: {exc}") from exc
        return np.asarray(recorded[:, 0], dtype=np.float64)

    return play_record
