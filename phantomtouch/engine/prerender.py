"""Short plans rendered whole before they play, in the requesting thread and by the
voice's own renderer, so the callback's ``PatternVoice`` only adds their samples, bit for
bit the voice's (docs/engine.md, What a voice costs)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phantomtouch.renderer import PatternRenderer
from phantomtouch.renderer.plan import Plan

PRERENDER_MAX_S = 1.0
"""Longest plan rendered whole before it plays, s."""


@dataclass(frozen=True)
class Prerendered:
    """A plan's whole output: ``samples``, shape (frames, channels), float32,
    C-contiguous, read-only."""

    samples: np.ndarray


def prerender(plan: Plan) -> Prerendered:
    """Render ``plan`` whole (any length; see :data:`PRERENDER_MAX_S` for what is worth it)."""
    samples = np.empty((plan.frames, plan.channels), dtype=np.float32)
    PatternRenderer(plan).render_into(samples)
    samples.flags.writeable = False
    return Prerendered(samples=samples)
