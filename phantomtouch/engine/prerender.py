"""Short plans rendered whole before they play, so the audio callback only adds samples.

A pattern voice that renders in the audio callback pays for its first frames in the
block it begins in, and for every later chunk while it sounds
(:mod:`phantomtouch.engine.voices`). For a short touch — a tap on a collision, at most
``PRERENDER_MAX_S`` long — that work is done once, when the touch is scheduled, in the
requesting thread: :func:`prerender` renders the plan with the same
:class:`~phantomtouch.renderer.PatternRenderer`, so its samples are exactly those the
voice would have rendered (the renderer's output does not depend on how it is cut into
blocks), and the callback's :class:`~phantomtouch.engine.voices.PrerenderedVoice` adds
slices of them: whole-width frames, one contiguous add a block.

:class:`PrerenderCache` keeps the samples of the plans in use: a plan made once and
played often (a preset from the server's plan cache) is rendered once.
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from phantomtouch.renderer import PatternRenderer
from phantomtouch.renderer.plan import Plan

PRERENDER_MAX_S = 1.0
"""Longest plan rendered whole before it plays, s."""
PRERENDER_CACHE_BYTES = 32 << 20
"""Most bytes of samples a cache keeps."""


@dataclass(frozen=True)
class Prerendered:
    """A plan's whole output.

    Attributes
    ----------
    samples : ndarray, shape (frames, channels), float32, C-contiguous, read-only
    """

    samples: np.ndarray

    @property
    def frames(self) -> int:
        return int(self.samples.shape[0])


def prerender(plan: Plan) -> Prerendered:
    """Render ``plan`` whole (any length; see :data:`PRERENDER_MAX_S` for what is worth it)."""
    samples = np.empty((plan.frames, plan.channels), dtype=np.float32)
    PatternRenderer(plan).render_into(samples)
    samples.flags.writeable = False
    return Prerendered(samples=samples)


class PrerenderCache:
    """Prerendered short plans by plan identity, least recently used dropped first.

    Samples are kept while their plan lives and the cache stays within ``max_bytes``; any
    thread may call :meth:`get` (the render runs outside the cache's lock).

    Parameters
    ----------
    sample_rate_hz : int
    max_s : float
        Longest plan rendered whole, s; 0 renders none.
    max_bytes : int
    """

    def __init__(
        self,
        sample_rate_hz: int,
        *,
        max_s: float = PRERENDER_MAX_S,
        max_bytes: int = PRERENDER_CACHE_BYTES,
    ) -> None:
        self.max_frames = round(max_s * sample_rate_hz)
        self.max_bytes = int(max_bytes)
        self.bytes = 0
        self._lock = threading.Lock()
        self._prerendered: OrderedDict[int, tuple[weakref.ref[Plan], Prerendered]] = OrderedDict()

    def get(self, plan: Plan) -> Prerendered | None:
        """The samples of ``plan``, rendered now if need be; None for a plan too long."""
        if plan.frames > self.max_frames:
            return None
        with self._lock:
            known = self._prerendered.get(id(plan))
            if known is not None and known[0]() is plan:
                self._prerendered.move_to_end(id(plan))
                return known[1]
        prerendered = prerender(plan)
        with self._lock:
            self._drop(id(plan))
            self._prerendered[id(plan)] = (weakref.ref(plan), prerendered)
            self.bytes += prerendered.samples.nbytes
            while self.bytes > self.max_bytes and len(self._prerendered) > 1:
                self._drop(next(iter(self._prerendered)))
        return prerendered

    def _drop(self, key: int) -> None:
        old = self._prerendered.pop(key, None)
        if old is not None:
            self.bytes -= old[1].samples.nbytes
