"""Admission by budget: how many pattern voices may sound, and begin, at once
(``docs/engine.md``)."""

from __future__ import annotations

import math
from collections import Counter

from phantomtouch.errors import EngineBusyError
from phantomtouch.schema.device import DeviceProfile

RENDER_BUDGET = 0.5
"""Default share of a block's playing time that pattern voices may take to render."""
START_SHARE = 0.2
"""Share of a block's playing time that voices beginning in it may take."""
CHURN_SHARE = 0.15
"""Share of the callback's time, on average, that the first frames of beginning voices
may take."""
CHURN_WINDOW_S = 0.1
"""Over how long a burst of beginnings may exceed ``CHURN_SHARE`` before it is refused."""
MAX_START_DELAY_S = 0.02
"""How far, s, a job asked for as soon as possible may move to a block with room."""


class Admission:
    """The voice, start and churn limits of one engine, from the measured costs (the
    front's lock held); unmeasured costs (0) leave them at ``max_voices`` and unbounded.

    Parameters
    ----------
    max_voices : int, >= 1
    render_budget : float, 0 < render_budget <= 1

    Attributes
    ----------
    voice_cost, start_cost, prerendered_cost : float
        Measured costs, shares of a block's playing time (0: not measured): a sounding
        voice that renders in the callback, a voice in the block it begins in, a sounding
        prerendered voice (:mod:`phantomtouch.engine.prerender`).
    """

    def __init__(self, device: DeviceProfile, *, max_voices: int, render_budget: float) -> None:
        self.sample_rate_hz = device.sample_rate_hz
        self.block_frames = device.block_frames
        self.max_voices = max_voices
        self.render_budget = float(render_budget)
        self.voice_cost = self.start_cost = self.prerendered_cost = 0.0
        self._starts: Counter[int] = Counter()  # block index: jobs that begin in it
        self._churn = 0.0  # first-chunk work admitted and not yet paid off, in blocks
        self._churn_block = 0.0

    def forget_starts(self) -> None:
        """A new engine process counts frames from 0 again."""
        self._starts.clear()
        self._churn = self._churn_block = 0.0

    def take_costs(self, costs: tuple[float, float, float] | None) -> None:
        """Take ``(voice_cost, start_cost, prerendered_cost)`` from
        :func:`~phantomtouch.engine.core.measure_costs`, unless None or known already."""
        if costs is not None and self.voice_cost <= 0.0:
            self.voice_cost, self.start_cost, self.prerendered_cost = map(float, costs)

    def cost(self, prerendered: bool) -> float:
        """What a job costs while it sounds: prerendered, or rendered in the callback."""
        return self.prerendered_cost if prerendered else self.voice_cost

    @property
    def voice_capacity(self) -> int:
        """Pattern voices that may sound at once: the budget over the measured cost of
        one voice, at most ``max_voices`` and at least 1."""
        cost = self.voice_cost
        by_budget = self.max_voices if cost <= 0 else math.floor(self.render_budget / cost)
        return max(1, min(self.max_voices, by_budget))

    @property
    def starts_per_block(self) -> int:
        """Pattern voices that may begin in one block: ``START_SHARE`` over the measured
        cost of a voice's first block (unbounded when it is not measured)."""
        if self.start_cost <= 0.0:
            return 1 << 30
        return max(1, math.floor(START_SHARE / self.start_cost))

    def begin(self, first: int, asap: bool, now_frames: int) -> int:
        """Admit the beginning at frame ``first`` of a job that renders in the callback, or
        refuse it (``EngineBusyError``), ``now_frames`` being the sample clock; returns the
        frame it is promised: ``first``, or up to ``MAX_START_DELAY_S`` later for a job
        asked for as soon as possible (``asap``); the churn account: ``docs/engine.md``."""
        if self.start_cost <= 0.0:
            return first
        size = self.block_frames
        now_block = now_frames / size
        paid = (now_block - self._churn_block) * CHURN_SHARE
        self._churn, self._churn_block = max(0.0, self._churn - paid), now_block
        window = CHURN_SHARE * CHURN_WINDOW_S * self.sample_rate_hz / size
        if self._churn + self.start_cost > max(window, self.start_cost):
            raise EngineBusyError(
                "touches begin faster than the engine can render their first frames "
                f"(at most {CHURN_SHARE:.0%} of its time); retry later"
            )
        self._churn += self.start_cost
        per_block = self.starts_per_block
        starts = self._starts
        for old in [b for b in starts if b < now_frames // size]:
            del starts[old]
        block = first // size
        if not asap and starts[block] >= per_block:
            raise EngineBusyError(
                f"{per_block} pattern voices already begin in the block of start_frame={first} "
                "(what one block can begin at once); choose another frame"
            )
        last = block + max(1, math.ceil(MAX_START_DELAY_S * self.sample_rate_hz / size))
        while starts[block] >= per_block:
            block += 1
            if block > last:
                raise EngineBusyError(
                    f"{per_block} pattern voices begin in every block of the next "
                    f"{MAX_START_DELAY_S * 1000:g} ms (what one block can begin at once); "
                    "retry later"
                )
        starts[block] += 1
        return max(first, block * size)
