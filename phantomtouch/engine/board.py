"""The control side of live contacts: validation, touchdowns, who is down.

:class:`ContactBoard` checks every argument (a bad one raises ParameterError naming it),
computes a touchdown's channel gains with the renderer's phantom gains (outside the
audio callback), posts moves as positions (the callback computes their gains, see
:mod:`phantomtouch.engine.contacts`), builds contact voices and keeps the contacts that
are down, keyed by ``(owner, contact)``. The engine calls it under its lock; building a
voice (a noise carrier's loop is computed on its first use) happens before the lock is
taken.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from phantomtouch.engine.checks import check_frame, check_id, check_range
from phantomtouch.engine.commands import CommandQueue
from phantomtouch.engine.contacts import ContactSettings, ContactVoice, Position, Target
from phantomtouch.errors import EngineBusyError, ParameterError, ProtocolError
from phantomtouch.renderer.carriers import make_source
from phantomtouch.renderer.gains import LAWS, gains_for_points
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.levels import amplitude_for_level, table_i_level_db
from phantomtouch.renderer.plan import check_carrier_frequencies
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import CombinedCarrier, NoiseCarrier, SineCarrier

MAX_VELOCITY_M_S = 10.0
_TRANSIENT_TIME_CONSTANTS = 7.0

CarrierModel = SineCarrier | NoiseCarrier | CombinedCarrier


def check_law(law: object) -> str:
    """An interpolation law of the renderer."""
    if not isinstance(law, str) or law not in LAWS:
        raise ParameterError(f"law={law!r} must be one of {sorted(LAWS)}")
    return law


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
    if not isinstance(carrier, SineCarrier | NoiseCarrier | CombinedCarrier):
        raise ParameterError(
            f"carrier={carrier!r} must be a SineCarrier, NoiseCarrier or CombinedCarrier"
        )
    check_carrier_frequencies(carrier, device.sample_rate_hz)
    return carrier


class ContactBoard:
    """Contacts that are down, and how to build, move and release them.

    Parameters
    ----------
    device : DeviceProfile
    settings : ContactSettings
    queue : CommandQueue
        Where touchdowns and releases go.
    """

    def __init__(self, device: DeviceProfile, settings: ContactSettings, queue: CommandQueue):
        self.device = device
        self.settings = settings
        self._queue = queue
        self._geometry = Geometry.for_device(device)
        self._contacts: dict[tuple[str, str], ContactVoice] = {}
        self._serials = itertools.count(1)
        sample_rate_hz = device.sample_rate_hz
        self.attack_frames = round(settings.attack_s * sample_rate_hz)
        self.release_frames = max(1, round(settings.release_s * sample_rate_hz))
        decay_frames = settings.transient_decay_s * sample_rate_hz
        n = np.arange(math.ceil(_TRANSIENT_TIME_CONSTANTS * decay_frames), dtype=np.float64)
        shape = np.exp(-n / decay_frames) * np.sin(
            2.0 * np.pi * settings.transient_freq_hz * n / sample_rate_hz
        )
        self._burst_shape = shape.astype(np.float32)
        full = settings.transient_intensity
        self._burst_amplitude = (
            amplitude_for_level(device.safety.max_level_db + 20.0 * math.log10(full), device)
            if full > 0
            else 0.0
        )

    def __len__(self) -> int:
        return len(self._contacts)

    # -- validation and building (no lock needed) -------------------------------------

    def burst(self, normal_velocity_m_s: object) -> np.ndarray | None:
        """The impact transient for a normal velocity, or None without one."""
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

    def amplitude(self, intensity: object, carrier: object) -> float:
        """Voice amplitude of a relative intensity (see :func:`contact_amplitude`)."""
        return contact_amplitude(self.device, intensity, carrier)

    def check_carrier(self, carrier: object) -> CarrierModel:
        """A carrier the device's sample rate can play (see :func:`check_contact_carrier`)."""
        return check_contact_carrier(self.device, carrier)

    def target(
        self, x_cm: object, y_cm: object, *, amplitude: float, law: str, frame: int | None
    ) -> Target:
        """Gains of a position; points outside the layout are projected onto it."""
        x = check_range("x_cm", x_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm")
        y = check_range("y_cm", y_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm")
        unit, _ = gains_for_points(self._geometry, np.array([[x, y]]), law=law, mode="2d")
        unit32 = unit[0].astype(np.float32)
        return Target(
            serial=next(self._serials),
            x_cm=x,
            y_cm=y,
            gains=unit32 * np.float32(amplitude),
            unit_gains=unit32,
            amplitude=amplitude,
            frame=frame,
        )

    def prepare_down(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None,
        carrier: object,
        law: str,
        normal_velocity_m_s: float | None,
        at_frame: int | None,
    ) -> ContactVoice:
        """Check a touchdown and build its voice (see :meth:`Engine.contact_down`)."""
        check_id("owner", owner)
        check_id("contact", contact)
        law = check_law(law)
        checked = self.check_carrier(carrier)
        amplitude = self.amplitude(intensity, checked)
        frame = check_frame("at_frame", at_frame)
        target = self.target(x_cm, y_cm, amplitude=amplitude, law=law, frame=frame)
        return ContactVoice(
            owner=owner,
            contact=contact,
            source=make_source(checked, self.device.sample_rate_hz),
            target=target,
            attack_frames=self.attack_frames,
            release_frames=self.release_frames,
            law=law,
            down_burst=self.burst(normal_velocity_m_s),
        )

    # -- the contacts that are down (under the engine's lock) -------------------------

    def down(self, voice: ContactVoice, first_frame: int, asap: bool) -> None:
        """Start a prepared voice; a contact already down under its id is released."""
        key = (voice.owner, voice.contact)
        old = self._contacts.get(key)
        if old is None and len(self._contacts) >= self.settings.max_contacts:
            raise EngineBusyError(
                f"{len(self._contacts)} contacts are down; at most "
                f"max_contacts={self.settings.max_contacts}"
            )
        self._queue.push_start(voice, first_frame, asap)
        if old is not None:
            self._queue.push_release(old, voice.down_target.frame)
        self._contacts[key] = voice

    def move(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None,
        at_frame: int | None,
    ) -> None:
        """Post the newest position of a contact that is down."""
        check_id("owner", owner)
        check_id("contact", contact)
        frame = check_frame("at_frame", at_frame)
        voice = self._contacts.get((owner, contact))
        if voice is None:
            raise ProtocolError(
                f"contact={contact!r} of owner={owner!r} is not down: expected down, got move"
            )
        x = check_range("x_cm", x_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm")
        y = check_range("y_cm", y_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm")
        self.post(voice, x, y, intensity, frame)

    def post_checked(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        """Post a position checked by the sender already; a contact not down is ignored.

        Needs no lock (the audio callback posts what another process wrote).
        """
        voice = self._contacts.get((owner, contact))
        if voice is not None:
            self.post(voice, x_cm, y_cm, intensity, frame)

    def post(
        self,
        voice: ContactVoice,
        x_cm: float,
        y_cm: float,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        """Replace the voice's mailbox with a position (None intensity: unchanged)."""
        amplitude = (
            voice.mailbox.amplitude if intensity is None else self.amplitude(intensity, None)
        )
        voice.mailbox = Position(next(self._serials), x_cm, y_cm, amplitude, frame)

    def up(
        self, owner: str, contact: str, *, normal_velocity_m_s: object, at_frame: int | None
    ) -> None:
        """Release a contact (ignored when it is not down)."""
        check_id("owner", owner)
        check_id("contact", contact)
        frame = check_frame("at_frame", at_frame)
        burst = self.burst(normal_velocity_m_s)
        voice = self._contacts.pop((owner, contact), None)
        if voice is not None:
            self._queue.push_release(voice, frame, burst)

    def release_owner(self, owner: str) -> None:
        """Release every contact of ``owner``."""
        for key in [key for key in self._contacts if key[0] == owner]:
            self._queue.push_release(self._contacts.pop(key), None)

    def forget_all(self) -> None:
        """Forget every contact (``stop_all`` releases their voices)."""
        self._contacts.clear()

    def positions(self) -> list[dict[str, Any]]:
        """``{"owner", "contact", "x_cm", "y_cm"}`` of every contact that is down."""
        return [
            {"owner": owner, "contact": contact, "x_cm": v.mailbox.x_cm, "y_cm": v.mailbox.y_cm}
            for (owner, contact), v in self._contacts.items()
        ]
