"""Short plans rendered whole before they play, so the audio callback only adds samples.

A pattern voice that renders in the audio callback pays for its first chunk in the block
it begins in, and for every later chunk while it sounds (:mod:`phantomtouch.engine.voices`).
For a short touch — a tap on a collision, at most ``CLIP_MAX_S`` long — that work is done
once, when the touch is scheduled, in the requesting thread: :func:`render_clip` renders
the plan with the same :class:`~phantomtouch.renderer.PatternRenderer`, so a clip holds
exactly the samples the voice would have rendered (the renderer's output does not depend
on how it is cut into blocks), and the callback's :class:`~phantomtouch.engine.voices.ClipVoice`
adds slices of it: whole-width frames, one contiguous add a block.

:class:`ClipCache` keeps the clips of the plans in use: a plan made once and played
often (a preset from the server's plan cache) is rendered once.
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from phantomtouch.renderer import PatternRenderer
from phantomtouch.renderer.plan import Plan

CLIP_MAX_S = 1.0
"""Longest plan rendered as a clip, s."""
CLIP_CACHE_BYTES = 32 << 20
"""Most bytes of clips a cache keeps."""


@dataclass(frozen=True)
class Clip:
    """A plan's whole output.

    Attributes
    ----------
    samples : ndarray, shape (frames, channels), float32, C-contiguous, read-only
    """

    samples: np.ndarray

    @property
    def frames(self) -> int:
        return int(self.samples.shape[0])


def render_clip(plan: Plan) -> Clip:
    """Render ``plan`` whole (any length; see :data:`CLIP_MAX_S` for what is worth it)."""
    samples = np.empty((plan.frames, plan.channels), dtype=np.float32)
    PatternRenderer(plan).render_into(samples)
    samples.flags.writeable = False
    return Clip(samples=samples)


class ClipCache:
    """Clips of short plans by plan identity, least recently used dropped first.

    A clip is kept while its plan lives and the cache stays within ``max_bytes``; any
    thread may call :meth:`get` (the render runs outside the cache's lock).

    Parameters
    ----------
    sample_rate_hz : int
    max_s : float
        Longest plan rendered as a clip, s; 0 renders none.
    max_bytes : int
    """

    def __init__(
        self, sample_rate_hz: int, *, max_s: float = CLIP_MAX_S, max_bytes: int = CLIP_CACHE_BYTES
    ) -> None:
        self.max_frames = round(max_s * sample_rate_hz)
        self.max_bytes = int(max_bytes)
        self.bytes = 0
        self._lock = threading.Lock()
        self._clips: OrderedDict[int, tuple[weakref.ref[Plan], Clip]] = OrderedDict()

    def get(self, plan: Plan) -> Clip | None:
        """The clip of ``plan``, rendered now if need be; None for a plan too long."""
        if plan.frames > self.max_frames:
            return None
        with self._lock:
            known = self._clips.get(id(plan))
            if known is not None and known[0]() is plan:
                self._clips.move_to_end(id(plan))
                return known[1]
        clip = render_clip(plan)
        with self._lock:
            self._drop(id(plan))
            self._clips[id(plan)] = (weakref.ref(plan), clip)
            self.bytes += clip.samples.nbytes
            while self.bytes > self.max_bytes and len(self._clips) > 1:
                self._drop(next(iter(self._clips)))
        return clip

    def _drop(self, key: int) -> None:
        old = self._clips.pop(key, None)
        if old is not None:
            self.bytes -= old[1].samples.nbytes
