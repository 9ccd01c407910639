"""Several patterns at their own start times, mixed offline as the engine mixes them.

A score (a ``.tact`` project's voices, :mod:`phantomtouch.clips.tact_score`) is a list of
``(start_s, pattern)``. The engine plays each pattern as a voice from its start frame,
:func:`voice_frame` after the score's first frame, sums the voices and passes the sum
through the output stage; :func:`render_timed` does the same offline, so a score rendered
to a file and the same score played carry the same samples (as long as the engine's
limiter, which only acts above the ceiling, stays idle).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.output import OutputStage
from phantomtouch.renderer.render import plan_at
from phantomtouch.renderer.voice import PatternRenderer
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

_BLOCK_FRAMES = 1 << 16


def voice_frame(start_s: float, sample_rate_hz: int) -> int:
    """The frame, counted from the score's first, at which a voice starting ``start_s`` in
    begins: ``round(start_s * sample_rate_hz)``; the one rounding both paths use."""
    return round(start_s * sample_rate_hz)


def render_timed(
    voices: Sequence[tuple[float, TouchPattern]],
    device: DeviceProfile | None = None,
    *,
    sample_rate_hz: int | None = None,
    duration_s: float | None = None,
) -> np.ndarray:
    """Render patterns that start at their own times into one signal.

    Parameters
    ----------
    voices : sequence of (float, TouchPattern)
        ``(start_s, pattern)``; ``start_s`` >= 0, s after the signal's first frame.
    device : DeviceProfile or None
        None: the paper's armband.
    sample_rate_hz : int or None
        None: the device's.
    duration_s : float or None
        Length of the signal, s (at least long enough for every voice; None: until the
        last voice ends).

    Returns
    -------
    ndarray, shape (frames, channels), float32
        The voices summed, then calibrated and limited (the output stage); finite, within
        the device's ceiling. Any thread; pure.
    """
    planned = []
    for start_s, pattern in voices:
        if not (np.isfinite(start_s) and 0.0 <= start_s <= limits.MAX_DURATION_S):
            raise ParameterError(
                f"start_s={start_s!r} must be within [0, {limits.MAX_DURATION_S:g}] s"
            )
        planned.append(plan_at(pattern, device, sample_rate_hz=sample_rate_hz))
    base = device or DeviceProfile.default()
    rate = sample_rate_hz or base.sample_rate_hz
    starts = [voice_frame(start_s, rate) for start_s, _ in voices]
    end = max((s + p.frames for s, p in zip(starts, planned, strict=True)), default=0)
    if duration_s is not None:
        if not (np.isfinite(duration_s) and 0.0 <= duration_s <= limits.MAX_DURATION_S):
            raise ParameterError(
                f"duration_s={duration_s!r} must be within [0, {limits.MAX_DURATION_S:g}] s"
            )
        end = max(end, round(duration_s * rate))
    channels = base.channels
    out = np.zeros((end, channels), dtype=np.float32)
    for start, resolved in zip(starts, planned, strict=True):
        voice = PatternRenderer(resolved)
        at = start
        while not voice.finished:
            frames = min(_BLOCK_FRAMES, voice.remaining_frames)
            voice.render_add(out[at : at + frames])
            at += frames
    stage = OutputStage(
        base if sample_rate_hz is None else base.model_copy(update={"sample_rate_hz": rate})
    )
    for first in range(0, end, _BLOCK_FRAMES):
        stage.process(out[first : first + _BLOCK_FRAMES])
    return out
