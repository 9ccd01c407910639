"""A touchdown's checks and computations, done once, by the front, outside real time: a
bad carrier, intensity or velocity raises ParameterError naming it; the audio side only
builds the voice from the gains, amplitude and transient computed here."""

from __future__ import annotations

import math

import numpy as np

from phantomtouch.engine.checks import check_range
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.errors import ParameterError
from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.levels import amplitude_for_level, table_i_level_db
from phantomtouch.renderer.plan import check_carrier_frequencies
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import CombinedCarrier, NoiseCarrier, SineCarrier

MAX_VELOCITY_M_S = 10.0
_TRANSIENT_TIME_CONSTANTS = 7.0

CarrierModel = SineCarrier | NoiseCarrier | CombinedCarrier


def contact_amplitude(device: DeviceProfile, intensity: object, carrier: object) -> float:
    """Voice amplitude of a relative intensity (None: Table I "low" for the carrier)."""
    max_db = device.safety.max_level_db
    if intensity is None:
        level_db = table_i_level_db("low", carrier)
        if level_db > max_db:
            raise ParameterError(
                f"intensity=None gives Table I 'low' = {level_db:g} dB re 1 µm/s²; the "
                f"device allows at most safety.max_level_db={max_db:g} dB"
            )
        return amplitude_for_level(level_db, device)
    relative = check_range("intensity", intensity, 0.0, 1.0, "(1 = safety.max_level_db)")
    if relative == 0.0:
        return 0.0
    return amplitude_for_level(max_db + 20.0 * math.log10(relative), device)


def check_contact_carrier(device: DeviceProfile, carrier: object) -> CarrierModel:
    """A carrier the device's sample rate can play (None: a 100 Hz sine)."""
    if carrier is None:
        return SineCarrier()
    if not isinstance(carrier, CarrierModel):
        raise ParameterError(
            f"carrier={carrier!r} must be a SineCarrier, NoiseCarrier or CombinedCarrier"
        )
    check_carrier_frequencies(carrier, device.sample_rate_hz)
    return carrier


class Touchdowns:
    """Gains and transients of touchdowns and lift-offs, for ``device`` as ``settings`` say
    (the front's threads)."""

    def __init__(self, device: DeviceProfile, settings: ContactSettings) -> None:
        self.settings = settings
        self._geometry = Geometry.for_device(device)
        decay_frames = settings.transient_decay_s * device.sample_rate_hz
        n = np.arange(math.ceil(_TRANSIENT_TIME_CONSTANTS * decay_frames), dtype=np.float64)
        omega_rad_s = 2.0 * np.pi * settings.transient_freq_hz
        shape = np.exp(-n / decay_frames) * np.sin(omega_rad_s * n / device.sample_rate_hz)
        self._burst_shape = shape.astype(np.float32)
        self._burst_amplitude = contact_amplitude(device, settings.transient_intensity, None)

    def burst(self, normal_velocity_m_s: object) -> np.ndarray | None:
        """The impact transient for a normal velocity, m/s, or None without one; raises
        ParameterError when it is not within +-``MAX_VELOCITY_M_S``."""
        if normal_velocity_m_s is None:
            return None
        velocity = check_range(
            "normal_velocity_m_s", normal_velocity_m_s, -MAX_VELOCITY_M_S, MAX_VELOCITY_M_S, "m/s"
        )
        scale = min(1.0, abs(velocity) / self.settings.transient_full_velocity_m_s)
        amplitude = scale * self._burst_amplitude
        if amplitude <= 0.0:
            return None
        return self._burst_shape * np.float32(amplitude)

    def unit_gains(self, x_cm: float, y_cm: float, law: str) -> np.ndarray:
        """Phantom gains of a checked position, shape (channels,), float32; points outside
        the layout are projected onto it."""
        unit, _ = gains_for_points(self._geometry, np.array([[x_cm, y_cm]]), law=law, mode="2d")
        return unit[0].astype(np.float32)
