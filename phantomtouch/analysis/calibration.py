"""Calibrate an armband: measure each actuator, design its correction, verify the levels.

Per output channel, with an accelerometer on that channel's actuator:

1. **Excite**: band-limited noise (default 20-1000 Hz, the renderer's Butterworth noise)
   on that channel alone, recorded through a sound-card input.
2. **Estimate** the transfer function drive -> acceleration (Welch's H1, latency
   removed; :func:`~phantomtouch.analysis.inverse_filter.estimate_transfer`).
3. **Invert**: a Tikhonov-regularised inverse, flat over 40-500 Hz and rolling off
   around it, realised as a minimum-phase FIR scaled to 1 at ``f_ref``
   (:func:`~phantomtouch.analysis.inverse_filter.inverse_fir`).
4. **Store**: ``calibration.channel_level_db`` gets each channel's level of a
   full-scale sine at ``f_ref`` (the output stage scales each channel by
   ``10 ** ((reference_level_db - channel_level_db) / 20)``) and
   ``calibration.fir_taps`` the correction's shape.
5. **Verify**: sines at 50, 100 and 150 Hz and band noise rendered by the renderer with
   the calibrated profile (so the real output stage with its FIR is what is verified),
   played and recorded, their levels compared with the requested ones.

The measurement loop is a function ``play_record(drive) -> recorded``: the sound card
through :func:`~phantomtouch.analysis.sound_input.sounddevice_loop`, or the digital twin through
:class:`~phantomtouch.analysis.twin.TwinLoop`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy import signal

from phantomtouch.analysis.inverse_filter import (
    BAND_HZ,
    Transfer,
    estimate_delay,
    estimate_transfer,
    fir_gain,
    inverse_fir,
)
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

VERIFY_FREQS_HZ = (50.0, 100.0, 150.0)
_MIN_COHERENCE = 0.5


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
