"""Meta Haptics Studio's ``.haptic`` (the Lofelt format it descends from) to a clip.

The file is JSON::

    {"version": {"major": 1, "minor": 0, "patch": 0},
     "metadata": {...},
     "signals": {"continuous": {"envelopes": {
         "amplitude": [{"time": 0.0, "amplitude": 0.2},
                       {"time": 0.1, "amplitude": 1.0,
                        "emphasis": {"amplitude": 1.0, "frequency": 0.7}}],
         "frequency": [{"time": 0.0, "frequency": 0.5}]}}}}

Times in seconds; amplitude and frequency 0-1, joined by straight lines. An ``emphasis``
on an amplitude breakpoint is a transient at that breakpoint's time. Checked as Lofelt's
data model v1 and its validator have it: ``version`` with ``major`` 1 (``minor`` and
``patch`` optional); an amplitude envelope of at least one breakpoint; a frequency
envelope optional, and empty allowed (the clip then keeps the middle frequency, 0.5);
times at least 0 and never decreasing within an envelope (two breakpoints at one time
are a step); an emphasis' amplitude not below its breakpoint's. Keys this does not use
(``metadata``, and whatever later minor versions add) are ignored. docs/clips.md shows a
whole file and the rules.
"""

from __future__ import annotations

from typing import Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.schema.clip import (
    MAX_CLIP_POINTS,
    Breakpoint,
    ClipTime,
    HapticClip,
    Transient,
    Unit,
)
from phantomtouch.schema.validation import check_never_decreasing


class _Lenient(BaseModel):
    model_config = ConfigDict(extra="ignore", frozen=True)


class Emphasis(_Lenient):
    amplitude: Unit
    frequency: Unit


class AmplitudePoint(_Lenient):
    time: ClipTime
    amplitude: Unit
    emphasis: Emphasis | None = None

    @model_validator(mode="after")
    def _emphasis_above(self) -> Self:
        if self.emphasis is not None and self.emphasis.amplitude < self.amplitude:
            raise ValueError(
                f"emphasis.amplitude={self.emphasis.amplitude!r} is below the breakpoint's "
                f"amplitude={self.amplitude!r}; an emphasis is at least as strong as its "
                "breakpoint (Lofelt's rule)"
            )
        return self


class FrequencyPoint(_Lenient):
    time: ClipTime
    frequency: Unit


_STEP = "; equal times are a step"
"""What an equal time means in a ``.haptic`` envelope, said beside the rule."""


class Version(_Lenient):
    major: Literal[1] = Field(description="The format's major version: 1.")
    minor: int = Field(default=0, ge=0)
    patch: int = Field(default=0, ge=0)


class Envelopes(_Lenient):
    amplitude: list[AmplitudePoint] = Field(min_length=1, max_length=MAX_CLIP_POINTS)
    frequency: list[FrequencyPoint] | None = Field(default=None, max_length=MAX_CLIP_POINTS)

    @model_validator(mode="after")
    def _times(self) -> Self:
        check_never_decreasing(
            [p.time for p in self.amplitude], "amplitude", time_name="time", note=_STEP
        )
        check_never_decreasing(
            [p.time for p in self.frequency or []], "frequency", time_name="time", note=_STEP
        )
        return self


class Continuous(_Lenient):
    envelopes: Envelopes


class Signals(_Lenient):
    continuous: Continuous


class HapticFile(_Lenient):
    """The parts of a ``.haptic`` document a clip is made of."""

    version: Version
    signals: Signals


def clip_of_haptic(document: HapticFile) -> HapticClip:
    """The clip a validated ``.haptic`` document describes."""
    envelopes = document.signals.continuous.envelopes
    amplitude = [Breakpoint(t_s=p.time, value=p.amplitude) for p in envelopes.amplitude]
    frequency = [Breakpoint(t_s=p.time, value=p.frequency) for p in envelopes.frequency or []]
    transients = [
        Transient(t_s=p.time, amplitude=p.emphasis.amplitude, frequency=p.emphasis.frequency)
        for p in envelopes.amplitude
        if p.emphasis is not None
    ]
    end_s = max([amplitude[-1].t_s, *(p.t_s for p in frequency[-1:])])
    return HapticClip(
        duration_s=end_s if end_s > 0.0 else _TRANSIENT_ONLY_S,
        amplitude=amplitude,
        transients=transients,
        **({"frequency": frequency} if frequency else {}),
    )


_TRANSIENT_ONLY_S = 0.1
"""Length of a clip whose envelopes all sit at time 0 (a lone emphasis), s."""
