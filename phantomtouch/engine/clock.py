"""The sample clock: how frames handed to the sink map to the server clock.

Callbacks arrive with jitter but are never early, so :class:`SampleClock` follows the
earliest arrivals at once and later ones only slowly; a callback far later than the
model (a stalled stream) re-anchors it.
"""

from __future__ import annotations

import abc
import math
import time
from collections.abc import Callable

FOLLOW = 1.0 / 256.0
"""Fraction of a late arrival the clock moves towards per block."""
RESYNC_S = 0.05
"""A callback this much later than the model re-anchors the clock, s."""
LATENCY_FOLLOW = 1.0 / 16.0
"""Fraction of a new output-latency reading the latency moves towards per block."""


class FrameMapping(abc.ABC):
    """Maps frames of the engine's output to seconds on the server clock and back."""

    sample_rate_hz: int

    @abc.abstractmethod
    def anchor(self) -> tuple[int, float, float]:
        """``(anchor_frame, anchor_s, output_latency_s)``: the block from ``anchor_frame``
        was computed at server time ``anchor_s`` (any thread)."""

    def time_at(self, frame: int) -> float:
        """Server time, s, at which ``frame`` leaves the sound card (host)."""
        anchor_frame, anchor_s, latency_s = self.anchor()
        return anchor_s + (frame - anchor_frame) / self.sample_rate_hz + latency_s

    def frames_at(self, server_time_s: float) -> int:
        """The frame that leaves the sound card at ``server_time_s``, nearest (host)."""
        anchor_frame, anchor_s, latency_s = self.anchor()
        offset_s = server_time_s - latency_s - anchor_s
        return anchor_frame + math.floor(offset_s * self.sample_rate_hz + 0.5)


class SampleClock(FrameMapping):
    """The audio side's clock, following the times its blocks are computed at.

    Parameters
    ----------
    sample_rate_hz : int, > 0
    now_s : float or None
        Server time of frame 0; None: ``time.monotonic()``.
    publish : callable or None
        Called as ``publish(anchor_frame, anchor_s, output_latency_s)`` after every
        change (from the thread that made it), to share the clock with another process.
    """

    def __init__(
        self,
        sample_rate_hz: int,
        *,
        now_s: float | None = None,
        publish: Callable[[int, float, float], None] | None = None,
    ) -> None:
        self.sample_rate_hz = int(sample_rate_hz)
        self._latency_s = 0.0
        self._dac_seen = False
        self._anchor: tuple[int, float] = (0, time.monotonic() if now_s is None else now_s)
        self._publish = publish
        self._changed()

    def _changed(self) -> None:
        if self._publish is not None:
            self._publish(*self.anchor())

    @property
    def output_latency_s(self) -> float:
        """Time from a block's computation to its first frame leaving the sound card, s."""
        return self._latency_s

    @output_latency_s.setter
    def output_latency_s(self, value: float) -> None:
        self._latency_s = float(value)
        self._changed()

    def restart(self, frame: int, now_s: float) -> None:
        """Anchor the clock: ``frame`` is computed at server time ``now_s``."""
        self._anchor = (int(frame), float(now_s))
        self._changed()

    def observe(self, frame: int, now_s: float, dac_delay_s: float | None = None) -> None:
        """The block starting at ``frame`` is computed at ``now_s`` (audio callback).

        ``dac_delay_s``, when the sound card tells it (PortAudio's ``outputBufferDacTime``
        less its ``currentTime``), is how long until this block's first frame reaches the
        converter: the output latency follows it (smoothed over about 16 blocks; the
        first reading is taken as it is). Constant time, no allocation beyond one tuple.
        """
        if dac_delay_s is not None and 0.0 < dac_delay_s < 1.0:
            if self._dac_seen:
                self._latency_s += (dac_delay_s - self._latency_s) * LATENCY_FOLLOW
            else:
                self._latency_s, self._dac_seen = dac_delay_s, True
        anchor_frame, anchor_s = self._anchor
        predicted_s = anchor_s + (frame - anchor_frame) / self.sample_rate_hz
        late_s = now_s - predicted_s
        if late_s < 0.0 or late_s > RESYNC_S:
            self._anchor = (frame, now_s)
        else:
            self._anchor = (frame, predicted_s + late_s * FOLLOW)
        self._changed()

    def anchor(self) -> tuple[int, float, float]:
        return self._anchor[0], self._anchor[1], self._latency_s
