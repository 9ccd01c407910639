"""Digital twin of the armband: one resonator per actuator, drive signal -> acceleration.

Model (an assumption, not a measurement): each voice coil pressed on the skin is a
mass-spring-damper driven by the coil's force, which is proportional to the drive
signal. The acceleration of the moving mass then follows the second-order high-pass

    H(s) = g (s / w0)^2 / ((s / w0)^2 + (s / w0) / Q + 1),    w0 = 2 pi f0_hz,

flat (``g``) well above the resonance (mass controlled), rising by ``Q`` at it
(``|H(j w0)| = g Q``), falling as ``f^2`` below it (stiffness controlled). The default
parameters, ``f0_hz = 170`` and ``Q = 3``, are assumptions, not measurements: a
wide-band voice coil pressed on forearm skin is taken to resonate somewhere around
150-200 Hz with a Q of 2-5 (the skin adds stiffness and damping). ``phantomtouch
calibrate`` measures the real response of each actuator. ``g`` is set so that a full-scale sine at
``ref_hz`` gives ``level_db``, by default the device's calibration reference.

Discretisation: the bilinear transform with the frequency warped at ``f0_hz``
(:meth:`ActuatorModel.sos`). It maps the left half s-plane into the unit disc, so the
digital resonator is stable for every ``Q > 0`` and every ``0 < f0_hz < fs / 2``, and
its gain at ``f0_hz`` is exactly the analog ``g Q``. :func:`euler_accelerations` is
the naive explicit-Euler integration of the same equation, kept only to show where it
fails: its poles are ``1 + T s_k``, outside the unit circle as soon as
``2 pi f0_hz Q / fs > 1`` (docs/algorithms.md, sec. 9).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from phantomtouch.errors import ParameterError
from phantomtouch.schema.device import DeviceProfile

MICRO_M_S2 = 1e-6
"""Reference of acceleration levels: 1 µm/s², in m/s²."""

DEFAULT_F0_HZ = 170.0
"""Assumed resonance of a wide-band voice coil loaded by forearm skin."""
DEFAULT_Q = 3.0
"""Assumed quality factor of that resonance (skin damping: Q of 2-5)."""
DEFAULT_REF_HZ = 100.0
"""Frequency at which a model's ``level_db`` is met (the paper's main carrier)."""


def amplitude_m_s2(level_db: float) -> float:
    """Peak of a sine, m/s², whose RMS has ``level_db`` (dB re 1 µm/s²)."""
    return math.sqrt(2.0) * MICRO_M_S2 * 10.0 ** (level_db / 20.0)


@dataclass(frozen=True)
class ActuatorModel:
    """One actuator on the skin as a second-order resonator (see the module docstring).

    Parameters
    ----------
    f0_hz : float, > 0
        Resonance of the loaded actuator.
    q : float, > 0
        Quality factor of the resonance.
    level_db : float, finite
        Acceleration level, dB re 1 µm/s² RMS, of a full-scale sine at ``ref_hz``.
    ref_hz : float, > 0
        Frequency at which ``level_db`` holds.
    """

    f0_hz: float = DEFAULT_F0_HZ
    q: float = DEFAULT_Q
    level_db: float = 155.0
    ref_hz: float = DEFAULT_REF_HZ

    def __post_init__(self) -> None:
        for name in ("f0_hz", "q", "ref_hz"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError(f"{name}={value!r} must be finite and > 0")
        if not math.isfinite(self.level_db):
            raise ParameterError(f"level_db={self.level_db!r} must be finite")

    def _shape(self, freq_hz: np.ndarray) -> np.ndarray:
        """``H(j 2 pi f) / g``: the resonator without its gain."""
        s = 1j * np.asarray(freq_hz, dtype=np.float64) / self.f0_hz
        return np.asarray(s**2 / (s**2 + s / self.q + 1.0))

    @property
    def gain_m_s2(self) -> float:
        """``g``: acceleration amplitude, m/s², per unit drive far above the resonance."""
        return amplitude_m_s2(self.level_db) / float(abs(self._shape(np.array(self.ref_hz))))

    def response(self, freq_hz: np.ndarray | float) -> np.ndarray:
        """Analog frequency response, m/s² (peak) per unit drive amplitude, complex."""
        return self.gain_m_s2 * self._shape(np.asarray(freq_hz, dtype=np.float64))

    def sos(self, sample_rate_hz: float) -> np.ndarray:
        """The digital resonator: bilinear transform warped at ``f0_hz``.

        Returns
        -------
        ndarray, shape (1, 6)
            One second-order section ``[b0, b1, b2, 1, a1, a2]``.

        Raises
        ------
        ParameterError
            ``f0_hz`` is not below the Nyquist frequency ``sample_rate_hz / 2``.
        """
        nyquist = sample_rate_hz / 2.0
        if not 0.0 < self.f0_hz < nyquist:
            raise ParameterError(
                f"f0_hz={self.f0_hz!r} must be below the Nyquist frequency {nyquist:g} Hz"
            )
        # s / w0 = c (1 - 1/z) / (1 + 1/z): the warping puts the analog w0 exactly at f0_hz.
        c = 1.0 / math.tan(math.pi * self.f0_hz / sample_rate_hz)
        g = self.gain_m_s2
        a0 = c * c + c / self.q + 1.0
        b = np.array([1.0, -2.0, 1.0]) * (g * c * c / a0)
        a = np.array([a0, 2.0 - 2.0 * c * c, c * c - c / self.q + 1.0]) / a0
        return np.concatenate([b, a])[None, :]

    def poles_z(self, sample_rate_hz: float) -> np.ndarray:
        """Poles of :meth:`sos` in the z-plane, shape (2,), complex."""
        return np.roots(self.sos(sample_rate_hz)[0, 3:])

    def euler_poles_z(self, sample_rate_hz: float) -> np.ndarray:
        """Poles of the explicit-Euler integration, ``1 + s_k / fs``, shape (2,)."""
        w0 = 2.0 * math.pi * self.f0_hz
        poles_s = np.roots([1.0, w0 / self.q, w0 * w0])
        return np.asarray(1.0 + poles_s / sample_rate_hz)


def euler_accelerations(
    model: ActuatorModel, drive: np.ndarray, *, sample_rate_hz: float
) -> np.ndarray:
    """The same resonator integrated with explicit Euler: the naive way, for comparison.

    ``x'' + (w0 / Q) x' + w0^2 x = u`` with ``x += T x'``, ``x' += T x''`` per sample
    and the acceleration ``g x''``. Unstable when ``2 pi f0_hz Q / fs > 1``.

    Returns
    -------
    ndarray, shape (frames,), float64; may overflow to inf or NaN where unstable.
    """
    w0 = 2.0 * math.pi * model.f0_hz
    damping, stiffness = w0 / model.q, w0 * w0
    step = 1.0 / sample_rate_hz
    u = np.asarray(drive, dtype=np.float64)
    out = np.empty(len(u))
    x = v = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for n, un in enumerate(u.tolist()):
            accel = un * stiffness - damping * v - stiffness * x  # u scaled: H(inf) = 1
            out[n] = accel
            x += step * v
            v += step * accel
    return out * (model.gain_m_s2 / stiffness)


class ArmbandTwin:
    """The armband's actuators as resonators: drive blocks in, acceleration blocks out.

    Parameters
    ----------
    device : DeviceProfile
    models : sequence of ActuatorModel, one per output channel, or None
        None: the default model on every channel, with ``level_db`` at the device's
        ``calibration.reference_level_db`` (a nominal, uncalibrated armband).
    sample_rate_hz : int or None
        None: the device's rate.

    Notes
    -----
    Blocks are processed in order; the filter state carries over, so any block split
    gives the same samples as one call.
    """

    def __init__(
        self,
        device: DeviceProfile,
        models: Sequence[ActuatorModel] | None = None,
        *,
        sample_rate_hz: int | None = None,
    ) -> None:
        self.sample_rate_hz = int(sample_rate_hz or device.sample_rate_hz)
        if models is None:
            models = [ActuatorModel(level_db=device.calibration.reference_level_db)] * (
                device.channels
            )
        if len(models) != device.channels:
            raise ParameterError(
                f"models has {len(models)} entries; the device has {device.channels} channels"
            )
        self.models = tuple(models)
        self._sos = [m.sos(self.sample_rate_hz) for m in self.models]
        self._state = [np.zeros((1, 2)) for _ in self.models]

    def reset(self) -> None:
        """Bring every actuator to rest."""
        for state in self._state:
            state[:] = 0.0

    def process(self, drive: np.ndarray) -> np.ndarray:
        """Acceleration of every actuator, m/s².

        Parameters
        ----------
        drive : ndarray, shape (frames, channels)
            Output-stage signal (full scale = 1).

        Returns
        -------
        ndarray, shape (frames, channels), float64
        """
        drive = np.asarray(drive)
        if drive.ndim != 2 or drive.shape[1] != len(self.models):
            raise ParameterError(
                f"drive has shape {drive.shape}; expected (frames, {len(self.models)})"
            )
        out = np.empty(drive.shape, dtype=np.float64)
        for ch, sos in enumerate(self._sos):
            out[:, ch], self._state[ch] = signal.sosfilt(
                sos, drive[:, ch].astype(np.float64), zi=self._state[ch]
            )
        return out


class TwinLoop:
    """An in-process measurement loop: sound-card output -> twin -> accelerometer input.

    Stands in for ``sounddevice.playrec`` with an accelerometer on one actuator: the
    drive of every channel goes through that channel's actuator model, the actuator
    under the sensor (:attr:`sensor_channel`) is what the input records, delayed by the
    sound card's round-trip latency, scaled to input units and with sensor noise added.

    Parameters
    ----------
    twin : ArmbandTwin
    input_scale_m_s2 : float, > 0
        Acceleration, m/s², that reads as 1.0 (digital full scale) on the input.
    latency_frames : int, >= 0
        Round-trip latency of the sound card.
    noise_rms : float, >= 0
        RMS of the input noise, in input units.
    seed : int
        Seed of the noise.
    """

    def __init__(
        self,
        twin: ArmbandTwin,
        *,
        input_scale_m_s2: float,
        latency_frames: int = 0,
        noise_rms: float = 0.0,
        seed: int = 0,
    ) -> None:
        if not input_scale_m_s2 > 0.0:
            raise ParameterError(f"input_scale_m_s2={input_scale_m_s2!r} must be > 0")
        if latency_frames < 0 or noise_rms < 0.0:
            raise ParameterError(
                f"latency_frames={latency_frames!r} and noise_rms={noise_rms!r} must be >= 0"
            )
        self.twin = twin
        self.input_scale_m_s2 = float(input_scale_m_s2)
        self.latency_frames = int(latency_frames)
        self.noise_rms = float(noise_rms)
        self.sensor_channel = 1
        self._rng = np.random.default_rng(seed)

    def place_sensor(self, channel: int) -> None:
        """Move the accelerometer onto the actuator of output ``channel`` (1-based)."""
        if not 1 <= channel <= len(self.twin.models):
            raise ParameterError(f"channel={channel!r} must be within [1, {len(self.twin.models)}]")
        self.sensor_channel = channel

    def __call__(self, drive: np.ndarray) -> np.ndarray:
        """Play ``drive`` (frames, channels) and record the sensor, shape (frames,)."""
        self.twin.reset()
        acceleration = self.twin.process(drive)[:, self.sensor_channel - 1]
        recorded = np.zeros(len(acceleration))
        frames = max(0, len(acceleration) - self.latency_frames)
        recorded[self.latency_frames :] = acceleration[:frames] / self.input_scale_m_s2
        if self.noise_rms > 0.0:
            recorded += self._rng.normal(0.0, self.noise_rms, len(recorded))
        return recorded


def simulated_loop(device: DeviceProfile, *, input_scale_m_s2: float, seed: int = 0) -> TwinLoop:
    """A :class:`TwinLoop` for a dry run: every actuator different, as on a real arm.

    Resonances uniform in 140-210 Hz, Q in 2-5, levels within ±6 dB of the device's
    reference, 10 ms of sound-card latency and input noise 80 dB below full scale.
    """
    rng = np.random.default_rng(seed)
    reference = device.calibration.reference_level_db
    models = [
        ActuatorModel(
            f0_hz=float(rng.uniform(140.0, 210.0)),
            q=float(rng.uniform(2.0, 5.0)),
            level_db=reference + float(rng.uniform(-6.0, 6.0)),
        )
        for _ in range(device.channels)
    ]
    return TwinLoop(
        ArmbandTwin(device, models),
        input_scale_m_s2=input_scale_m_s2,
        latency_frames=round(0.010 * device.sample_rate_hz),
        noise_rms=1e-4,
        seed=seed,
    )
