"""The audio side of live contacts: the contacts that sound, keyed by ``(owner, contact)``.

:class:`ContactBoard` builds a contact voice from a touchdown the front checked and
computed (:class:`~phantomtouch.engine.messages.ContactDown`: gains, amplitude, transient),
posts moves as positions (the callback computes their gains, see
:mod:`phantomtouch.engine.contacts`), and queues releases. It checks nothing and computes
no gains of a touchdown: that was done once, by the front. It runs where the messages are
performed: in the engine process's audio callback (real time), or in the calling thread
of the in-process engine, under the front's lock.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

from phantomtouch.engine.commands import CommandQueue
from phantomtouch.engine.contacts import ContactSettings, ContactVoice, Position, Target
from phantomtouch.engine.touchdown import contact_amplitude
from phantomtouch.renderer.carriers import make_source
from phantomtouch.schema.device import DeviceProfile

if TYPE_CHECKING:
    from phantomtouch.engine.messages import ContactDown


class ContactBoard:
    """Contacts that sound, and how to start, move and release them.

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
        self._contacts: dict[tuple[str, str], ContactVoice] = {}
        self._serials = itertools.count(1)
        sample_rate_hz = device.sample_rate_hz
        self.attack_frames = round(settings.attack_s * sample_rate_hz)
        self.release_frames = max(1, round(settings.release_s * sample_rate_hz))

    def __len__(self) -> int:
        return len(self._contacts)

    def voice(self, down: ContactDown) -> ContactVoice:
        """The voice of a touchdown (real time: a sine source, or a noise loop handed over
        before; LookupError for a loop that was not).

        Raises
        ------
        LookupError
            The carrier's noise loop was not handed to this process.
        """
        unit = down.unit_gains
        target = Target(
            serial=next(self._serials),
            x_cm=down.x_cm,
            y_cm=down.y_cm,
            gains=unit * np.float32(down.amplitude),
            unit_gains=unit,
            amplitude=down.amplitude,
            frame=down.frame,
        )
        return ContactVoice(
            owner=down.owner,
            contact=down.contact,
            source=make_source(down.carrier, self.device.sample_rate_hz),
            target=target,
            attack_frames=self.attack_frames,
            release_frames=self.release_frames,
            law=down.law,
            down_burst=down.burst,
        )

    def down(self, voice: ContactVoice, first_frame: int, asap: bool) -> None:
        """Start a voice; a contact already sounding under its id is released."""
        key = (voice.owner, voice.contact)
        old = self._contacts.get(key)
        self._queue.push_start(voice, first_frame, asap)
        if old is not None:
            self._queue.push_release(old, voice.down_target.frame)
        self._contacts[key] = voice

    def post_checked(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        """Post a position checked by the front; a contact not sounding is ignored.

        Replaces the voice's mailbox (None intensity: the amplitude is unchanged).
        """
        voice = self._contacts.get((owner, contact))
        if voice is None:
            return
        amplitude = (
            voice.mailbox.amplitude
            if intensity is None
            else contact_amplitude(self.device, intensity, None)
        )
        voice.mailbox = Position(next(self._serials), x_cm, y_cm, amplitude, frame)

    def up(self, owner: str, contact: str, burst: np.ndarray | None, frame: int | None) -> None:
        """Release a contact with an optional transient (ignored when it is not sounding)."""
        voice = self._contacts.pop((owner, contact), None)
        if voice is not None:
            self._queue.push_release(voice, frame, burst)

    def release_owner(self, owner: str) -> None:
        """Release every contact of ``owner``."""
        for key in [key for key in self._contacts if key[0] == owner]:
            self._queue.push_release(self._contacts.pop(key), None)

    def clear(self) -> None:
        """Forget every contact (a ``stop_all`` fades their voices out)."""
        self._contacts.clear()
