"""Live contacts: a hand touching the forearm, moved by the newest position, struck by
an impact transient (how: ``docs/engine.md``, "Live contacts")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from phantomtouch.engine.checks import check_int, check_range
from phantomtouch.engine.future_mix import AHEAD_FRAMES
from phantomtouch.engine.voices import RingPool, Voice, Workspace
from phantomtouch.renderer.carriers import CarrierSource, SineSource, sine_blocks

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
    """One posted position of a contact, its gains computed by the host."""

    serial: int
    """Increases with every post; the callback applies a position once."""
    unit_gains: np.ndarray
    """Phantom gains of the position (projected onto the layout), shape (channels,),
    float32, each in [0, 1]: the callback only ramps to them."""
    amplitude: float
    """The contact's amplitude from this position on."""
    frame: int | None
    """Frame at which the position applies; None: the next block."""


class ContactVoice(Voice):
    """One live contact: a carrier at a moving phantom position (real time, in the audio
    callback; the side that posts moves only writes :attr:`mailbox`, a :class:`Position`
    with its gains, which :meth:`take_position` applies).

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
        self.mailbox = Position(serial, down.unit_gains, down.amplitude, down.frame)
        self._source = source
        self._attack_frames = int(attack_frames)
        self._applied = serial
        self._unit = down.unit_gains
        self._gains = self._target = down.unit_gains * np.float32(down.amplitude)
        self._carrier_frames = 0
        self.carrier_ahead = (
            np.empty(AHEAD_FRAMES, dtype=np.float32) if isinstance(source, SineSource) else None
        )
        """A sine carrier's next samples, computed ahead by :class:`ContactMix` (None for
        any other carrier): frames ``ahead_first .. ahead_first + ahead_frames``."""
        self.ahead_first = 0
        self.ahead_frames = 0
        self._down_burst = down.burst
        self._bursts: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]] = []

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

    def take_position(self, block_start: int, block_end: int, work: Workspace) -> None:
        """Ramp towards the newest position across the block ``block_start ..
        block_end`` when it is not applied yet and is due before ``block_end``."""
        box = self.mailbox
        if box.serial == self._applied or (box.frame is not None and box.frame >= block_end):
            return
        if box.frame is not None and box.frame < block_start and self.start_frame <= block_start:
            work.late_commands += 1
        self._applied = box.serial
        self._unit = box.unit_gains
        self._target = box.unit_gains * np.float32(box.amplitude)

    def sounds_through(self, block_start: int, block_end: int) -> bool:
        """It sounds from ``block_start`` to ``block_end`` (neither starts nor falls silent
        within the block): :meth:`ContactMix.render` takes it with the others."""
        silent_from = self.silent_from
        return self.start_frame <= block_start and (silent_from is None or silent_from >= block_end)

    @property
    def source(self) -> CarrierSource:
        """Its carrier's samples."""
        return self._source

    def advance_carrier(self, frames: int) -> int:
        """The carrier's first frame for a block of ``frames``; the carrier moves on by
        the block."""
        first = self._carrier_frames
        self._carrier_frames = first + frames
        return first

    def envelope(self, block_start: int, frames: int, work: Workspace) -> np.ndarray | None:
        """Its attack or release envelope over a block it sounds through, shape (frames,),
        float32, a view of ``work`` (None: 1 throughout)."""
        return self._envelope(block_start, frames, work)

    @property
    def gains(self) -> np.ndarray:
        """Its gains where the last block ended, shape (channels,), float32."""
        return self._gains

    @property
    def target(self) -> np.ndarray:
        """The gains it ramps to across this block (:attr:`gains` when it stays put)."""
        return self._target

    def end_block(self, mix: np.ndarray, block_start: int) -> bool:
        """After :meth:`ContactMix.render` took its carrier: its gains reach their target, its
        bursts are added into ``mix`` (frames, channels); True once it is silent for good."""
        self._gains = self._target
        if self._bursts:
            self._add_bursts(mix, block_start)
        silent_from = self.silent_from
        ended = silent_from is not None and block_start + mix.shape[0] >= silent_from
        return ended and not self._bursts

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        frames = mix.shape[0]
        block_end = block_start + frames
        offset = max(0, self.start_frame - block_start)
        first = block_start + offset
        count = frames - offset
        silent_from = self.silent_from
        if silent_from is not None:
            count = min(count, silent_from - first)
        if count > 0:
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
        start = self._gains
        if self._target is start:
            block = signal[:, None] * start
        else:
            block = work.ramp_of(count)[:, None] * (self._target - start)
            block += start
            block *= signal[:, None]
        dest += block

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


class ContactMix:
    """The sum of the contacts that sound through a block, in one compiled loop.

    With carriers ``c`` (contacts, frames), gains ``s`` where the last block ended and
    ``d = target - s`` (contacts, channels), the contacts' sum at frame ``k`` is
    ``(c.T @ s)[k] + ramp[k] * (c.T @ d)[k]``, ``ramp[k] = (k + 1) / frames``: each
    contact's gains ramped linearly across the block, in float64
    (:func:`~phantomtouch.renderer.kernels.add_contacts`). Buffers for up to
    :attr:`capacity` contacts, grown when more sound (non real time on construction).

    Parameters
    ----------
    block_frames, channels : int, >= 1
    capacity : int, >= 1
    """

    def __init__(self, block_frames: int, channels: int, capacity: int = 8) -> None:
        self.block_frames = int(block_frames)
        self.channels = int(channels)
        self._ramp = self._ramp_for(self.block_frames)
        self._index = np.arange(max(AHEAD_FRAMES, self.block_frames), dtype=np.float64)
        from phantomtouch.renderer import kernels  # numba: loaded with a mix, not at import

        self._add_contacts = kernels.add_contacts
        self._allocate(int(capacity))
        self.count = 0
        self.moved = False

    def _allocate(self, capacity: int) -> None:
        self.capacity = capacity
        self.carriers = np.empty((capacity, self.block_frames))
        self.starts = np.empty((capacity, self.channels))
        self.targets = np.empty((capacity, self.channels))
        self._sine_rows = np.empty(capacity, dtype=np.intp)
        self._sine_starts = np.empty(capacity)
        self._sine_cycles = np.empty(capacity)
        ahead = self._index.shape[0]
        self._sines = np.empty((capacity, ahead), dtype=np.float32)
        self._phases = np.empty((2, capacity, ahead))
        self._steady = np.empty(capacity * ahead)
        self._steady_rows = self._steady[:0].reshape(0, 0)
        self._steady_voices: list[ContactVoice] = []
        self._steady_used = 0
        self._steady_end = -1
        self._row_starts: list[np.ndarray | None] = [None] * capacity
        self._row_targets: list[np.ndarray | None] = [None] * capacity
        self._taken = self.carriers[:0].T

    def render(
        self,
        contacts: list[ContactVoice],
        block_start: int,
        work: Workspace,
        out: np.ndarray,
        add: bool,
    ) -> bool:
        """The sum of ``contacts`` (each sounding through the block from ``block_start``)
        into ``out`` (frames, channels), float32: added to it when ``add``, else written;
        summed in float64 and rounded once. True when every sample of ``out`` is finite
        after it. Their carriers move on by the block (real time).
        :meth:`ContactVoice.end_block` ends each one's block.

        While the same sine contacts sound on without an envelope (the steady state of a
        scene's hands), their carriers are one slice of :attr:`_steady`, the next
        ``AHEAD_FRAMES`` of each computed together
        (:func:`~phantomtouch.renderer.carriers.sine_blocks`) whenever they run out or the
        contacts change, and a row of gains is written only when it changed: no copy per
        contact. Otherwise each one's carrier is copied into :attr:`carriers`: a sine's
        from its own :attr:`~ContactVoice.carrier_ahead` (those that ran out computed
        together), any other carrier's block by block, then times its envelope. Both give
        each sine's samples bit for bit (the phase of frame ``n`` is ``n`` times the cycles
        per frame whatever the block)."""
        count = len(contacts)
        frames = out.shape[0]
        if count > self.capacity:  # more contacts than ever before: room for twice as many
            self._allocate(2 * count)
        self.count = count
        starts, targets = self.starts, self.targets
        row_starts, row_targets = self._row_starts, self._row_targets
        firsts: list[int] = []
        moved = False
        plain = True  # no contact has an envelope over this block
        for row, voice in enumerate(contacts):
            firsts.append(voice.advance_carrier(frames))
            gains, target = voice.gains, voice.target
            if row_starts[row] is not gains:  # each row written only when it changed
                starts[row] = gains
                row_starts[row] = gains
            if row_targets[row] is not target:
                targets[row] = target
                row_targets[row] = target
            if target is not gains:
                moved = True
            if plain and voice.envelope(block_start, frames, work) is not None:
                plain = False
        used = self._steady_used
        if (
            plain
            and block_start == self._steady_end  # the last block took them so too, and
            and contacts == self._steady_voices  # of the same voices: each moved on by it
            and used + frames <= self._index.shape[0]
        ):
            self._taken = self._steady_rows[used : used + frames]
            self._steady_used = used + frames
            self._steady_end = block_start + frames
        elif plain and all(voice.carrier_ahead is not None for voice in contacts):
            self._fill_steady(contacts, firsts)
            self._taken = self._steady_rows[:frames]
            self._steady_used = frames
            self._steady_end = block_start + frames
        else:
            self._copy_carriers(contacts, firsts, block_start, frames, work)
        self.moved = moved
        return self._sum(self._taken, self.starts[:count], self.targets[:count], out, add)

    def _fill_steady(self, contacts: list[ContactVoice], firsts: list[int]) -> None:
        """Compute the next ``AHEAD_FRAMES`` of every contact's sine from ``firsts`` into
        :attr:`_steady`, float64."""
        count = len(contacts)
        self._sine_starts[:count] = firsts
        ahead = self._index.shape[0]
        self._steady_rows = self._steady[: ahead * count].reshape(ahead, count)
        np.copyto(self._steady_rows, self._next_sines(contacts).T)
        self._steady_voices = list(contacts)

    def _copy_carriers(
        self,
        contacts: list[ContactVoice],
        firsts: list[int],
        block_start: int,
        frames: int,
        work: Workspace,
    ) -> None:
        """Copy each contact's carrier into :attr:`carriers` (the sines that ran out of
        their own buffers computed together), times its envelope."""
        carriers = self.carriers[: len(contacts), :frames]
        sine_rows, sine_starts = self._sine_rows, self._sine_starts
        sines = 0
        for row, (voice, first) in enumerate(zip(contacts, firsts, strict=True)):
            ahead = voice.carrier_ahead
            if ahead is not None:
                at = first - voice.ahead_first
                if at + frames <= voice.ahead_frames:
                    carriers[row] = ahead[at : at + frames]
                else:
                    sine_rows[sines] = row
                    sine_starts[sines] = first
                    sines += 1
            else:
                carriers[row] = voice.source.block(first, frames)
        if sines:
            self._sines_ahead(contacts, sines, frames)
        for row, voice in enumerate(contacts):
            env = voice.envelope(block_start, frames, work)  # a view of work: used at once
            if env is not None:
                carriers[row] *= env
        self._taken = carriers.T

    def _sines_ahead(self, contacts: list[ContactVoice], sines: int, frames: int) -> None:
        """Compute the next ``AHEAD_FRAMES`` of the ``sines`` sine carriers that ran out
        (rows :attr:`_sine_rows`, first frames :attr:`_sine_starts`) together, and take
        this block's from them."""
        rows = self._sine_rows[:sines].tolist()
        voices = [contacts[row] for row in rows]
        blocks = self._next_sines(voices)
        for k, (row, voice) in enumerate(zip(rows, voices, strict=True)):
            ahead = voice.carrier_ahead
            assert ahead is not None
            kept = min(ahead.shape[0], blocks.shape[1])  # a block longer than it: none
            ahead[:kept] = blocks[k, :kept]
            voice.ahead_first = int(self._sine_starts[k])
            voice.ahead_frames = kept
            self.carriers[row, :frames] = blocks[k, :frames]

    def _next_sines(self, voices: list[ContactVoice]) -> np.ndarray:
        """The next ``AHEAD_FRAMES`` of the sine carriers of ``voices``, each from its first
        frame in :attr:`_sine_starts`, computed together, shape (voices, AHEAD_FRAMES),
        float32 (a view of :attr:`_sines`)."""
        count = len(voices)
        cycles = self._sine_cycles[:count]
        for k, voice in enumerate(voices):
            source = voice.source
            assert isinstance(source, SineSource)
            cycles[k] = source.cycles_per_frame
        return sine_blocks(
            self._sine_starts[:count],
            cycles,
            self._index,
            out=self._sines[:count],
            scratch=(self._phases[0, :count], self._phases[1, :count]),
        )

    def _sum(
        self,
        carriers: np.ndarray,
        starts: np.ndarray,
        targets: np.ndarray,
        out: np.ndarray,
        add: bool,
    ) -> bool:
        """``carriers @ starts + ramp * (carriers @ (targets - starts))`` into ``out``;
        ``carriers`` (frames, contacts), float64; True when ``out`` is finite after it."""
        frames = out.shape[0]
        ramp = self._ramp if frames == self.block_frames else self._ramp_for(frames)
        return bool(self._add_contacts(out, carriers, starts, targets, ramp, self.moved, add))

    @staticmethod
    def _ramp_for(frames: int) -> np.ndarray:
        """``(k + 1) / frames``, shape (frames,), float64."""
        return np.arange(1, frames + 1, dtype=np.float64) / frames

    def finite_rows(self) -> np.ndarray:
        """Which contacts of the last :meth:`render` have finite carriers and gains, shape
        (contacts,), bool."""
        count = self.count
        rows = np.isfinite(self._taken).all(axis=0)
        rows &= np.isfinite(self.starts[:count]).all(axis=1)
        rows &= np.isfinite(self.targets[:count]).all(axis=1)
        return np.asarray(rows)

    def add_sum_of(self, rows: np.ndarray, out: np.ndarray) -> None:
        """Add into ``out`` the sum of the last :meth:`render` over the contacts ``rows``
        (a bool mask) alone, as that call would have given it without the others (real
        time, rarely: a block that came out not finite)."""
        self._sum(
            self._taken[: out.shape[0], rows],
            self.starts[: self.count][rows],
            self.targets[: self.count][rows],
            out,
            True,
        )
