"""Short plans rendered whole before they play, so the audio callback only adds samples.

A pattern voice that renders in the audio callback pays for its first frames in the
block it begins in, and for every later chunk while it sounds
(:mod:`phantomtouch.engine.voices`). For a short touch — a tap on a collision, at most
``PRERENDER_MAX_S`` long — that work is done once, when the touch is scheduled, in the
requesting thread: :func:`prerender` renders the plan with the same
:class:`~phantomtouch.renderer.PatternRenderer`, so its samples are exactly those the
voice would have rendered (the renderer's output does not depend on how it is cut into
blocks), and the callback's :class:`~phantomtouch.engine.voices.PatternVoice` adds
slices of them: whole-width frames, one contiguous add a block.

The front's plan cache (:mod:`phantomtouch.engine.plans`) keeps the samples with their
plan: a plan made once and played often is rendered once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phantomtouch.renderer import PatternRenderer
from phantomtouch.renderer.plan import Plan

PRERENDER_MAX_S = 1.0
"""Longest plan rendered whole before it plays, s."""


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
