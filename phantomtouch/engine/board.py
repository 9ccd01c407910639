"""The contacts that sound on the audio side, keyed by the front's integer for each."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

from phantomtouch.engine.contacts import ContactSettings, ContactVoice, Position
from phantomtouch.engine.touchdown import contact_amplitude
from phantomtouch.engine.voice_queue import CommandQueue
from phantomtouch.schema.device import DeviceProfile

if TYPE_CHECKING:
    from phantomtouch.engine.messages import ContactDown
    from phantomtouch.renderer.carriers import CarrierSource


class ContactBoard:
    """Contacts that sound, started from touchdowns the front checked and computed, moved
    by posted positions, released into ``queue`` (a :class:`CommandQueue`); it checks
    nothing. Every method runs where the messages are performed: real time in the engine
    process's audio callback, or the calling thread of the in-process engine (under the
    front's lock). ``attack_frames`` (>= 0) and ``release_frames`` (>= 1) are the
    settings' ``attack_s`` and ``release_s`` in frames."""

    def __init__(self, device: DeviceProfile, settings: ContactSettings, queue: CommandQueue):
        self.device = device
        self._queue = queue
        self._contacts: dict[int, ContactVoice] = {}
        self._serials = itertools.count(1)
        self.attack_frames = round(settings.attack_s * device.sample_rate_hz)
        self.release_frames = max(1, round(settings.release_s * device.sample_rate_hz))

    def down(self, down: ContactDown, source: CarrierSource) -> None:
        """Start a touchdown's voice playing ``source`` (its carrier's) at ``down.frame``
        (None: the next block); a contact already sounding under its integer is released."""
        voice = ContactVoice(
            down, next(self._serials), source, self.attack_frames, self.release_frames
        )
        key = down.contact
        self._queue.push_start(voice, down.frame or 0, down.frame is None)
        if (old := self._contacts.get(key)) is not None:
            self._queue.push_release(old, down.frame)
        self._contacts[key] = voice

    def post_checked(
        self, contact: int, unit_gains: np.ndarray, intensity: float | None, frame: int | None
    ) -> None:
        """Post a position checked by the front, as its phantom gains (``unit_gains``, shape
        (channels,), float32, computed by the host), into the voice's mailbox (None
        intensity: the amplitude is unchanged); a contact not sounding is ignored."""
        voice = self._contacts.get(contact)
        if voice is None:
            return
        amplitude = voice.mailbox.amplitude
        if intensity is not None:
            amplitude = contact_amplitude(self.device, intensity, None)
        voice.mailbox = Position(next(self._serials), unit_gains, amplitude, frame)

    def up(self, contact: int, burst: np.ndarray | None, frame: int | None) -> None:
        """Release a contact with an optional transient (ignored when it is not sounding)."""
        voice = self._contacts.pop(contact, None)
        if voice is not None:
            self._queue.push_release(voice, frame, burst)

    def clear(self) -> None:
        """Forget every contact (a ``stop_all`` fades their voices out)."""
        self._contacts.clear()
