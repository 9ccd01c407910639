"""Triggered touches mixed ahead: the future-mix ring (``docs/engine.md``, What a voice
costs). Real time (the callback); construction is not."""

from __future__ import annotations

import numpy as np

from phantomtouch.engine.voices import PatternVoice

AHEAD_FRAMES = 1024
"""Frames the ring sums ahead at a time (8 blocks of 128 frames, 21 ms at 48 kHz): a
prerendered voice costs the callback one slice add per this many frames, and a stop or a
steal re-sums at most this many frames (plus a block) of every voice in the ring."""


class FutureMix:
    """The sum of the prerendered voices, summed ahead of the blocks that play it.

    A prerendered voice (a tap, a short score or clip: every sample known once it is
    planned) joins the ring when it begins; the callback then takes one slice of the ring
    a block instead of adding every voice. The ring holds frames ``[now, built)``, each the
    sum, in the order the voices began, of every voice's samples at that frame: a voice
    that begins is added at once over the frames built so far (it is the last in that
    order), and each new stretch of :attr:`ahead_frames` is zeroed and summed voice by
    voice. Nothing is ever subtracted: a release (a stop, a steal) changes a voice's
    samples from its frame on, and the ring is summed again from that frame from the
    voices it holds (:meth:`resum`), so every frame is the same float32 sum as adding the
    voices one by one, bit for bit.

    Parameters
    ----------
    block_frames, channels : int, >= 1
    ahead_frames : int, >= 1
        Frames summed ahead at a time (at least ``block_frames``).

    Attributes
    ----------
    voices : list of PatternVoice
        The voices in the ring, in the order they began.
    next_end : int or None
        The first frame from which some voice in the ring is silent for good (None while
        the ring holds none).
    """

    def __init__(self, block_frames: int, channels: int, ahead_frames: int = AHEAD_FRAMES) -> None:
        self.ahead_frames = max(int(ahead_frames), int(block_frames))
        size = 2 * self.ahead_frames + int(block_frames)
        self._sum = np.zeros((size, channels), dtype=np.float32)
        self._gain = np.empty(size, dtype=np.float32)
        self._index = np.arange(size, dtype=np.float32)
        self._base = 0  # the frame of the ring's first row
        self._built = 0  # frames [.., built) are summed
        self.voices: list[PatternVoice] = []
        self.next_end: int | None = None

    @property
    def summed_to(self) -> int:
        """The frame up to which the ring is summed (any thread, for a look only)."""
        return self._built

    def add(self, voice: PatternVoice, block_start: int) -> None:
        """Take ``voice`` (prerendered, beginning within the block from ``block_start``)
        into the ring, after every voice already there."""
        self.voices.append(voice)
        if self._built > block_start:
            lo = max(block_start, voice.start_frame)
            self._add(voice, lo, self._built)
        self._find_next_end()

    def take(self, out: np.ndarray, block_start: int) -> None:
        """Write the ring's frames ``block_start ..`` into ``out`` (frames, channels),
        summing the next stretch ahead first when the ring does not reach the block's end."""
        frames = out.shape[0]
        end = block_start + frames
        if self._built < end:
            self._build(block_start, end)
        at = block_start - self._base
        out[...] = self._sum[at : at + frames]

    def resum(self, frame: int, block_start: int) -> None:
        """Sum the ring again from ``frame`` (at least ``block_start``) on, from the voices
        it holds, in their order: after a voice's samples changed there (a release)."""
        lo = max(frame, block_start)
        if lo < self._built:
            self._sum[lo - self._base : self._built - self._base].fill(0.0)
            for voice in self.voices:
                self._add(voice, lo, self._built)
        self._find_next_end()

    def ended(self, block_end: int) -> list[PatternVoice]:
        """Take out and return the voices silent for good from ``block_end`` on (in
        order); the ring's frames do not change (those voices add nothing to them)."""
        ended = [voice for voice in self.voices if voice.silent_from <= block_end]
        self.voices = [voice for voice in self.voices if voice.silent_from > block_end]
        if not self.voices:
            self.clear()
        else:
            self._find_next_end()
        return ended

    def nonfinite(self, block_start: int, frames: int, row: np.ndarray) -> list[PatternVoice]:
        """The voices whose samples in the block are not finite, taken out of the ring,
        which is then summed again without them from ``block_start`` on. ``row`` (frames,
        channels), float32, is scratch (rarely: a block that came out not finite)."""
        bad: list[PatternVoice] = []
        for voice in self.voices:
            lo = max(block_start, voice.start_frame)
            hi = min(block_start + frames, voice.silent_from)
            if lo >= hi:
                continue
            piece = row[lo - block_start : hi - block_start]
            piece.fill(0.0)
            voice.mix_ahead(piece, lo, self._index, self._gain)
            if not np.isfinite(piece).all():
                bad.append(voice)
        if bad:
            self.voices = [voice for voice in self.voices if voice not in bad]
            self.resum(block_start, block_start)
        return bad

    def clear(self) -> None:
        """Forget every voice and every frame summed."""
        self.voices = []
        self.next_end = None
        self._base = self._built = 0

    def _build(self, block_start: int, end: int) -> None:
        if self._built < block_start:  # nothing summed for these frames yet
            self._base = self._built = block_start
        ahead = self.ahead_frames
        if self._built + ahead - self._base > self._sum.shape[0]:  # move the rest down
            kept = self._built - block_start
            at = block_start - self._base
            self._sum[:kept] = self._sum[at : at + kept]
            self._base = block_start
        while self._built < end:
            lo = self._built
            self._sum[lo - self._base : lo - self._base + ahead].fill(0.0)
            for voice in self.voices:
                self._add(voice, lo, lo + ahead)
            self._built = lo + ahead

    def _add(self, voice: PatternVoice, lo: int, hi: int) -> None:
        """Add ``voice``'s samples for frames ``lo .. hi`` into the ring."""
        lo = max(lo, voice.start_frame)
        hi = min(hi, voice.silent_from)
        if lo < hi:
            voice.mix_ahead(
                self._sum[lo - self._base : hi - self._base], lo, self._index, self._gain
            )

    def _find_next_end(self) -> None:
        self.next_end = min((voice.silent_from for voice in self.voices), default=None)
