"""Apple Core Haptics' ``.ahap`` to a clip.

The file is JSON: ``{"Version": 1.0, "Pattern": [entry, ...]}``, each entry one of

- ``{"Event": {"Time", "EventType", "EventDuration", "EventParameters": [{"ParameterID",
  "ParameterValue"}]}}``: ``HapticTransient`` (a click: ``HapticIntensity``,
  ``HapticSharpness``) or ``HapticContinuous`` (a tone for ``EventDuration`` s, with
  ``AttackTime`` and ``ReleaseTime`` ramps); audio events are ignored;
- ``{"Parameter": {"ParameterID", "Time", "ParameterValue"}}``: a dynamic parameter set
  from ``Time`` on;
- ``{"ParameterCurve": {"ParameterID", "Time", "ParameterCurveControlPoints": [{"Time",
  "ParameterValue"}]}}``: a dynamic parameter moving in straight lines between control
  points (their times counted from the curve's).

The clip: amplitude = ``min(1, sum of the continuous events' envelopes)`` times
``HapticIntensityControl`` (default 1); frequency = the intensity-weighted sharpness of
the sounding continuous events plus ``HapticSharpnessControl`` (default 0), within 0-1;
each transient event a transient with its intensity times the intensity control and its
sharpness plus the sharpness control. Attack and release ramps are straight lines here
(Core Haptics shapes them itself); the envelopes are sampled at every corner of the
events and curves and four times between, where two ramps multiply.
"""

from __future__ import annotations

import itertools
from typing import Literal, Self

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.schema.clip import MAX_CLIP_POINTS, Breakpoint, ClipTime, HapticClip, Transient

EventParameterId = Literal[
    "HapticIntensity",
    "HapticSharpness",
    "AttackTime",
    "DecayTime",
    "ReleaseTime",
    "Sustained",
    "AudioVolume",
    "AudioPan",
    "AudioPitch",
    "AudioBrightness",
]
DynamicParameterId = Literal[
    "HapticIntensityControl",
    "HapticSharpnessControl",
    "HapticAttackTimeControl",
    "HapticDecayTimeControl",
    "HapticReleaseTimeControl",
    "AudioVolumeControl",
    "AudioPanControl",
    "AudioPitchControl",
    "AudioBrightnessControl",
]
_SUBDIVISIONS = 4
_EMPTY_S = 0.1
"""Length of a clip with nothing but transients at time 0, s."""


class _Lenient(BaseModel):
    model_config = ConfigDict(extra="ignore", frozen=True)


class EventParameter(_Lenient):
    ParameterID: EventParameterId
    ParameterValue: float = Field(ge=-1.0, le=30.0, allow_inf_nan=False)


class AhapEvent(_Lenient):
    Time: ClipTime
    EventType: Literal["HapticTransient", "HapticContinuous", "AudioContinuous", "AudioCustom"]
    EventDuration: float | None = Field(default=None, gt=0.0, le=600.0, allow_inf_nan=False)
    EventParameters: list[EventParameter] = Field(default_factory=list, max_length=16)

    @model_validator(mode="after")
    def _duration(self) -> Self:
        if self.EventType == "HapticContinuous" and self.EventDuration is None:
            raise ValueError("EventDuration is required for a HapticContinuous event")
        return self

    def value(self, parameter: str, default: float) -> float:
        for p in self.EventParameters:
            if p.ParameterID == parameter:
                return p.ParameterValue
        return default


class AhapParameter(_Lenient):
    ParameterID: DynamicParameterId
    Time: ClipTime
    ParameterValue: float = Field(ge=-1.0, le=1.0, allow_inf_nan=False)


class ControlPoint(_Lenient):
    Time: ClipTime
    ParameterValue: float = Field(ge=-1.0, le=1.0, allow_inf_nan=False)


class AhapCurve(_Lenient):
    ParameterID: DynamicParameterId
    Time: ClipTime
    ParameterCurveControlPoints: list[ControlPoint] = Field(min_length=1, max_length=16_384)

    @model_validator(mode="after")
    def _increasing(self) -> Self:
        points = self.ParameterCurveControlPoints
        for i in range(1, len(points)):
            if points[i].Time < points[i - 1].Time:
                raise ValueError(
                    f"ParameterCurveControlPoints[{i}].Time={points[i].Time!r} is before the "
                    "point ahead of it; times never decrease"
                )
        return self


class Entry(_Lenient):
    Event: AhapEvent | None = None
    Parameter: AhapParameter | None = None
    ParameterCurve: AhapCurve | None = None

    @model_validator(mode="after")
    def _one(self) -> Self:
        given = [n for n in ("Event", "Parameter", "ParameterCurve") if getattr(self, n)]
        if len(given) != 1:
            raise ValueError(
                "each Pattern entry holds exactly one of Event, Parameter or ParameterCurve; "
                f"got {given or 'none'}"
            )
        return self


class AhapFile(_Lenient):
    """The parts of an ``.ahap`` document a clip is made of."""

    Version: float | None = None
    Pattern: list[Entry] = Field(min_length=1, max_length=MAX_CLIP_POINTS)


class _Control:
    """One dynamic parameter over time: steps (Parameter) and ramps (ParameterCurve)."""

    def __init__(self, default: float) -> None:
        self.default = default
        self.pieces: list[tuple[float, np.ndarray, np.ndarray]] = []

    def add_step(self, t_s: float, value: float) -> None:
        self.pieces.append((t_s, np.array([t_s]), np.array([value])))

    def add_curve(self, curve: AhapCurve) -> None:
        points = curve.ParameterCurveControlPoints
        times = curve.Time + np.array([p.Time for p in points])
        self.pieces.append((float(times[0]), times, np.array([p.ParameterValue for p in points])))

    def corners(self) -> list[float]:
        return [float(t) for _, times, _ in self.pieces for t in times]

    def at(self, t_s: float, *, left: bool) -> float:
        """The value at ``t_s``: the latest piece begun by then (strictly before, ``left``)."""
        value = self.default
        self.pieces.sort(key=lambda piece: piece[0])
        for start_s, times, values in self.pieces:
            if start_s < t_s or (start_s == t_s and not left):
                value = float(np.interp(t_s, times, values))
        return value


def clip_of_ahap(document: AhapFile) -> HapticClip:
    """The clip a validated ``.ahap`` document describes."""
    intensity = _Control(1.0)
    sharpness = _Control(0.0)
    continuous: list[AhapEvent] = []
    transients: list[AhapEvent] = []
    for entry in document.Pattern:
        if entry.Event is not None:
            if entry.Event.EventType == "HapticContinuous":
                continuous.append(entry.Event)
            elif entry.Event.EventType == "HapticTransient":
                transients.append(entry.Event)
        elif entry.Parameter is not None:
            control = _control(entry.Parameter.ParameterID, intensity, sharpness)
            if control is not None:
                control.add_step(entry.Parameter.Time, entry.Parameter.ParameterValue)
        elif entry.ParameterCurve is not None:
            control = _control(entry.ParameterCurve.ParameterID, intensity, sharpness)
            if control is not None:
                control.add_curve(entry.ParameterCurve)

    corners = {0.0, *intensity.corners(), *sharpness.corners()}
    for event in continuous:
        start, end = event.Time, event.Time + float(event.EventDuration or 0.0)
        attack, release = _ramps(event)
        corners |= {start, end, start + attack, end - release}
    end_s = max([*corners, *(e.Time for e in transients)])
    grid = sorted(t for t in corners if t <= end_s)
    fine = [
        a + (b - a) * k / _SUBDIVISIONS
        for a, b in itertools.pairwise(grid)
        for k in range(_SUBDIVISIONS)
    ] + [grid[-1]]

    amplitude: list[Breakpoint] = []
    frequency: list[Breakpoint] = []
    last_sharpness = 0.5
    for t_s in fine:
        for left in (True, False):
            level, sharp = _continuous_at(continuous, t_s, left=left)
            if sharp is not None:
                last_sharpness = sharp
            value_a = min(1.0, level) * min(1.0, max(0.0, intensity.at(t_s, left=left)))
            value_f = min(1.0, max(0.0, last_sharpness + sharpness.at(t_s, left=left)))
            _append(amplitude, t_s, value_a)
            _append(frequency, t_s, value_f)
    clicks = [
        Transient(
            t_s=e.Time,
            amplitude=min(1.0, max(0.0, e.value("HapticIntensity", 1.0)))
            * min(1.0, max(0.0, intensity.at(e.Time, left=False))),
            frequency=min(
                1.0, max(0.0, e.value("HapticSharpness", 0.5) + sharpness.at(e.Time, left=False))
            ),
        )
        for e in sorted(transients, key=lambda e: e.Time)
    ]
    return HapticClip(
        duration_s=end_s if end_s > 0.0 else _EMPTY_S,
        amplitude=amplitude,
        frequency=frequency,
        transients=clicks,
    )


def _control(parameter: str, intensity: _Control, sharpness: _Control) -> _Control | None:
    if parameter == "HapticIntensityControl":
        return intensity
    if parameter == "HapticSharpnessControl":
        return sharpness
    return None  # the others shape what a clip does not have (audio, ramp times)


def _ramps(event: AhapEvent) -> tuple[float, float]:
    duration = float(event.EventDuration or 0.0)
    attack = min(max(0.0, event.value("AttackTime", 0.0)), duration)
    release = min(max(0.0, event.value("ReleaseTime", 0.0)), duration - attack)
    return attack, release


def _continuous_at(
    events: list[AhapEvent], t_s: float, *, left: bool
) -> tuple[float, float | None]:
    """Summed envelope of the continuous events at ``t_s`` and their weighted sharpness
    (None when none sounds); ``left``: the limit from before ``t_s``."""
    total = 0.0
    weighted = 0.0
    for event in events:
        start, end = event.Time, event.Time + float(event.EventDuration or 0.0)
        inside = start < t_s <= end if left else start <= t_s < end
        if not inside:
            continue
        attack, release = _ramps(event)
        level = max(0.0, min(1.0, event.value("HapticIntensity", 1.0)))
        if attack > 0.0 and t_s < start + attack:
            level *= (t_s - start) / attack
        if release > 0.0 and t_s > end - release:
            level *= (end - t_s) / release
        total += level
        weighted += level * min(1.0, max(0.0, event.value("HapticSharpness", 0.5)))
    if total <= 0.0:
        return 0.0, None
    return total, weighted / total


def _append(points: list[Breakpoint], t_s: float, value: float) -> None:
    """Add a breakpoint, unless it repeats the last one or extends a flat run (a step
    keeps both of its sides)."""
    if points and points[-1].t_s == t_s and points[-1].value == value:
        return
    if len(points) >= 2 and points[-1].value == value == points[-2].value:
        points[-1] = Breakpoint(t_s=t_s, value=value)
        return
    points.append(Breakpoint(t_s=t_s, value=value))
