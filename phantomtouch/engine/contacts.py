"""Live contacts: a hand touching the forearm, moved by the newest position, struck by
an impact transient (how: ``docs/engine.md``, "Live contacts")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from phantomtouch.engine.checks import check_int, check_range
from phantomtouch.engine.voices import RingPool, Voice, Workspace
from phantomtouch.renderer.carriers import CarrierSource
from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.geometry import Geometry

if TYPE_CHECKING:
    from phantomtouch.engine.messages import ContactDown


@dataclass(frozen=True)
class ContactSettings:
    """How live contacts start, end and strike; every field is checked on construction."""

    attack_s: float = 0.01
    """Linear fade-in on touchdown, s, within [0, 5]."""
    release_s: float = 0.08
    """Linear fade-out on lift-off, and of a stopped job or a released client, s, within
    [0.001, 5]."""
    transient_freq_hz: float = 250.0
    """Frequency of the impact transient, Hz, within [1, 1000]."""
    transient_decay_s: float = 0.008
    """Time constant of its exponential decay, s, within [0.001, 0.5]."""
    transient_full_velocity_m_s: float = 0.5
    """Normal velocity of the hand that gives the full transient, m/s, within [0.01, 10]."""
    transient_intensity: float = 0.5
    """Full transient amplitude, a relative intensity within [0, 1] (1 = the device's
    ``safety.max_level_db``)."""
    max_contacts: int = 128
    """Most contacts down at once (all clients together), within [1, 4096]."""

    def __post_init__(self) -> None:
        check_range("attack_s", self.attack_s, 0.0, 5.0, "s")
        check_range("release_s", self.release_s, 0.001, 5.0, "s")
        check_range("transient_freq_hz", self.transient_freq_hz, 1.0, 1000.0, "Hz")
        check_range("transient_decay_s", self.transient_decay_s, 0.001, 0.5, "s")
        check_range(
            "transient_full_velocity_m_s", self.transient_full_velocity_m_s, 0.01, 10.0, "m/s"
        )
        check_range("transient_intensity", self.transient_intensity, 0.0, 1.0, "")
        check_int("max_contacts", self.max_contacts, 1, 4096)


@dataclass(frozen=True, slots=True)
class Position:
    """One posted position of a contact, before its gains are known."""

    serial: int
    """Increases with every post; the callback applies a position once."""
    x_cm: float
    y_cm: float
    """As given (before projection onto the layout)."""
    amplitude: float
    """The contact's amplitude from this position on."""
    frame: int | None
    """Frame at which the position applies; None: the next block."""


class ContactVoice(Voice):
    """One live contact: a carrier at a moving phantom position (real time, in the audio
    callback; the side that posts moves only writes :attr:`mailbox`, a :class:`Position`,
    which :func:`retarget_contacts` applies).

    Parameters
    ----------
    down : ContactDown
        The touchdown, checked and computed by the front.
    serial : int
        Serial of its first position.
    source : CarrierSource
        The carrier's samples.
    attack_frames, release_frames : int, >= 0 and >= 1
        Lengths of the fade-in on touchdown and of the fade-out on lift-off.
    """

    kind = "contact"

    def __init__(
        self,
        down: ContactDown,
        serial: int,
        source: CarrierSource,
        attack_frames: int,
        release_frames: int,
    ) -> None:
        super().__init__(release_frames)
        self.key = down.contact
        self.place = (down.x_cm, down.y_cm, down.amplitude)
        self.law = down.law
        self.mailbox = Position(serial, down.x_cm, down.y_cm, down.amplitude, down.frame)
        self._source = source
        self._attack_frames = int(attack_frames)
        self._applied = serial
        self._unit = down.unit_gains
        self._gains = self._target = down.unit_gains * np.float32(down.amplitude)
        self._set_channels(np.flatnonzero(self._gains))
        self._carrier_frames = 0
        self._down_burst = down.burst
        self._bursts: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]] = []

    def _set_channels(self, channels: np.ndarray) -> None:
        """The channels the gains drive; all of them are added when they span over half."""
        self._channels = channels
        self._channel_list: list[int] = channels.tolist()
        span = int(channels[-1] - channels[0]) + 1 if channels.size else 0
        self._wide = 2 * span > len(self._gains)

    def _level_before(self, frame: int) -> float:
        """Attack level of the frame before ``frame`` (1 without an attack)."""
        if self._attack_frames == 0:
            return 1.0
        return min(1.0, max(0.0, (frame - self.start_frame) / self._attack_frames))

    @property
    def silent_from(self) -> int | None:
        if self.release_frame is None:
            return None
        level = self._level_before(self.release_frame)
        return self.release_frame - 1 + math.ceil(level * self.release_frames)

    def begin(self, frame: int, pool: RingPool) -> None:
        super().begin(frame, pool)
        if self._down_burst is not None:
            self._add_burst(self._down_burst, frame)
            self._down_burst = None

    def release(
        self, frame: int, transient: object | None = None, fade_frames: int | None = None
    ) -> None:
        super().release(frame, None, fade_frames)
        if isinstance(transient, np.ndarray):
            self._add_burst(transient, frame)

    def _add_burst(self, burst: np.ndarray, frame: int) -> None:
        """Play ``burst`` from ``frame`` at the position's unit gains."""
        channels = np.flatnonzero(self._unit)
        self._bursts.append((burst, self._unit[channels], channels, frame))

    def pending(self, block_end: int) -> Position | None:
        """The newest position, when it is not applied yet and due before ``block_end``."""
        box = self.mailbox
        if box.serial != self._applied and (box.frame is None or box.frame < block_end):
            return box
        return None

    def retarget(
        self, position: Position, unit_gains: np.ndarray, block_start: int, work: Workspace
    ) -> None:
        """Ramp towards ``position`` in the block from ``block_start``; ``unit_gains``,
        shape (channels,), float32, are its phantom gains."""
        late = position.frame is not None and position.frame < block_start
        if late and self.start_frame <= block_start:
            work.late_commands += 1
        self._applied = position.serial
        self._unit = unit_gains
        self._target = unit_gains * np.float32(position.amplitude)
        self._set_channels(np.flatnonzero(self._gains + self._target))

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        frames = mix.shape[0]
        block_end = block_start + frames
        offset = max(0, self.start_frame - block_start)
        first = block_start + offset
        count = frames - offset
        silent_from = self.silent_from
        if silent_from is not None:
            count = min(count, silent_from - first)
        if count > 0 and self._channels.size:
            self._add_carrier(mix[offset : offset + count], first, work)
        self._gains = self._target
        if self._bursts:
            self._add_bursts(mix, block_start)
        return silent_from is not None and block_end >= silent_from and not self._bursts

    def _envelope(self, first: int, count: int, work: Workspace) -> np.ndarray | None:
        env = None
        attack = self._attack_frames
        if attack > 0 and first - self.start_frame + 1 < attack:
            env = work.env[:count]
            np.add(work.index[:count], np.float32(first - self.start_frame + 1), out=env)
            env *= np.float32(1.0 / attack)
            np.minimum(env, np.float32(1.0), out=env)
        release = self.release_frame
        if release is not None and release < first + count:
            level = self._level_before(release)
            fade = work.gain[:count]
            np.add(work.index[:count], np.float32(first - release + 1), out=fade)
            fade *= np.float32(-1.0 / self.release_frames)
            fade += np.float32(level)
            env = np.minimum(fade, np.float32(1.0) if env is None else env, out=fade)
            np.maximum(env, np.float32(0.0), out=env)
        return env

    def _add_carrier(self, dest: np.ndarray, first: int, work: Workspace) -> None:
        count = dest.shape[0]
        signal = self._source.block(self._carrier_frames, count)
        self._carrier_frames += count
        env = self._envelope(first, count, work)
        if env is not None:
            signal *= env
        # Over a wide span, all channels at once: a contiguous add beats one strided add per
        # channel. The others have gains 0 before and after, so they add zeros.
        channels = self._channels
        start = self._gains if self._wide else self._gains[channels]
        if self._target is self._gains:
            block = signal[:, None] * start
        else:
            ramp = (
                work.ramp
                if count == work.block_frames
                else (np.arange(1, count + 1, dtype=np.float64) / count).astype(np.float32)
            )
            target = self._target if self._wide else self._target[channels]
            block = ramp[:, None] * (target - start)
            block += start
            block *= signal[:, None]
        if self._wide:
            dest += block
            return
        for column, channel in enumerate(self._channel_list):  # cheaper than a fancy index
            dest[:, channel] += block[:, column]

    def _add_bursts(self, mix: np.ndarray, block_start: int) -> None:
        block_end = block_start + mix.shape[0]
        keep = []
        for burst, gains, channels, frame in self._bursts:
            lo = max(frame, block_start)
            hi = min(frame + burst.shape[0], block_end)
            if lo < hi:
                piece = burst[lo - frame : hi - frame, None] * gains
                mix[lo - block_start : hi - block_start, channels] += piece
            if frame + burst.shape[0] > block_end:
                keep.append((burst, gains, channels, frame))
        self._bursts = keep


def retarget_contacts(
    geometry: Geometry, voices: list[Voice], block_start: int, block_end: int, work: Workspace
) -> None:
    """Retarget every contact among ``voices`` with a position due before ``block_end``,
    the gains of all of them computed in one vectorised call per law (real time)."""
    due: dict[str, list[tuple[ContactVoice, Position]]] = {}
    for voice in voices:
        if isinstance(voice, ContactVoice) and (position := voice.pending(block_end)):
            due.setdefault(voice.law, []).append((voice, position))
    for law, moved in due.items():
        points = np.array([(p.x_cm, p.y_cm) for _, p in moved], dtype=np.float64)
        unit, _ = gains_for_points(geometry, points, law=law, mode="2d")
        unit32 = unit.astype(np.float32)
        for row, (voice, position) in enumerate(moved):
            voice.retarget(position, unit32[row], block_start, work)
