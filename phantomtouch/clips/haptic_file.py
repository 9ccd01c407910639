"""Meta Haptics Studio's ``.haptic`` (the Lofelt format it descends from) to a clip.

The file is JSON::

    {"version": {"major": 1, "minor": 0, "patch": 0},
     "metadata": {...},
     "signals": {"continuous": {"envelopes": {
         "amplitude": [{"time": 0.0, "amplitude": 0.2},
                       {"time": 0.1, "amplitude": 1.0,
                        "emphasis": {"amplitude": 0.9, "frequency": 0.7}}],
         "frequency": [{"time": 0.0, "frequency": 0.5}]}}}}

Times in seconds; amplitude and frequency 0-1, joined by straight lines. An ``emphasis``
on an amplitude breakpoint is a transient at that breakpoint's time. Keys this does not
use (``metadata``, and whatever later versions add) are ignored.
"""

from __future__ import annotations

from typing import Any, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.schema.clip import (
    MAX_CLIP_POINTS,
    Breakpoint,
    ClipTime,
    HapticClip,
    Transient,
    Unit,
)


class _Lenient(BaseModel):
    model_config = ConfigDict(extra="ignore", frozen=True)


class Emphasis(_Lenient):
    amplitude: Unit
    frequency: Unit


class AmplitudePoint(_Lenient):
    time: ClipTime
    amplitude: Unit
    emphasis: Emphasis | None = None


class FrequencyPoint(_Lenient):
    time: ClipTime
    frequency: Unit


def _increasing(points: list[Any], field: str) -> None:
    for i in range(1, len(points)):
        if points[i].time < points[i - 1].time:
            raise ValueError(
                f"{field}[{i}].time={points[i].time!r} is before {field}[{i - 1}].time="
                f"{points[i - 1].time!r}; times never decrease"
            )


class Envelopes(_Lenient):
    amplitude: list[AmplitudePoint] = Field(min_length=1, max_length=MAX_CLIP_POINTS)
    frequency: list[FrequencyPoint] = Field(default_factory=list, max_length=MAX_CLIP_POINTS)

    @model_validator(mode="after")
    def _times(self) -> Self:
        _increasing(self.amplitude, "amplitude")
        _increasing(self.frequency, "frequency")
        return self


class Continuous(_Lenient):
    envelopes: Envelopes


class Signals(_Lenient):
    continuous: Continuous


class HapticFile(_Lenient):
    """The parts of a ``.haptic`` document a clip is made of."""

    version: dict[str, Any] | None = None
    signals: Signals


def clip_of_haptic(document: HapticFile) -> HapticClip:
    """The clip a validated ``.haptic`` document describes."""
    envelopes = document.signals.continuous.envelopes
    amplitude = [Breakpoint(t_s=p.time, value=p.amplitude) for p in envelopes.amplitude]
    frequency = [Breakpoint(t_s=p.time, value=p.frequency) for p in envelopes.frequency]
    transients = [
        Transient(t_s=p.time, amplitude=p.emphasis.amplitude, frequency=p.emphasis.frequency)
        for p in envelopes.amplitude
        if p.emphasis is not None
    ]
    end_s = max([amplitude[-1].t_s, *(p.t_s for p in frequency[-1:])])
    return HapticClip(
        duration_s=end_s if end_s > 0.0 else _TRANSIENT_ONLY_S,
        amplitude=amplitude,
        frequency=frequency or [Breakpoint(t_s=0.0, value=0.5)],
        transients=transients,
    )


_TRANSIENT_ONLY_S = 0.1
"""Length of a clip whose envelopes all sit at time 0 (a lone emphasis), s."""
