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
events and curves and four times between, where two ramps multiply. The conversion takes
time linear in the file (:mod:`~phantomtouch.clips.ahap_envelope`; benchmarks/bench_clips.py).
"""

from __future__ import annotations

from typing import Literal, Self

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.clips.ahap_envelope import SOUNDING, Control, kept_points, summed_envelope
from phantomtouch.errors import ParameterError
from phantomtouch.schema.clip import MAX_CLIP_POINTS, ClipTime, HapticClip

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
DIGITS = 12
"""Decimals kept of each envelope value (the audio path is float32, 7 digits)."""
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


def clip_of_ahap(document: AhapFile) -> HapticClip:
    """The clip a validated ``.ahap`` document describes, in time linear in its entries.

    Raises
    ------
    ParameterError
        The clip would have more than ``MAX_CLIP_POINTS`` breakpoints in an envelope.
    """
    intensity = Control(1.0)
    sharpness = Control(0.0)
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
                control.add(
                    np.array([entry.Parameter.Time]), np.array([entry.Parameter.ParameterValue])
                )
        elif entry.ParameterCurve is not None:
            control = _control(entry.ParameterCurve.ParameterID, intensity, sharpness)
            if control is not None:
                curve = entry.ParameterCurve
                points = curve.ParameterCurveControlPoints
                control.add(
                    curve.Time + np.array([p.Time for p in points]),
                    np.array([p.ParameterValue for p in points]),
                )

    starts = np.array([e.Time for e in continuous], dtype=np.float64)
    ends = starts + np.array([float(e.EventDuration or 0.0) for e in continuous])
    ramps = np.array([_ramps(e) for e in continuous], dtype=np.float64).reshape(-1, 2)
    attacks, releases = ramps[:, 0], ramps[:, 1]
    levels = np.array([_unit(e.value("HapticIntensity", 1.0)) for e in continuous])
    weights = levels * np.array([_unit(e.value("HapticSharpness", 0.5)) for e in continuous])
    clicks_s = np.array(sorted(e.Time for e in transients), dtype=np.float64)
    grid = np.unique(
        np.concatenate(
            (
                [0.0],
                intensity.corners(),
                sharpness.corners(),
                starts,
                ends,
                starts + attacks,
                ends - releases,
            )
        )
    )
    end_s = float(max(grid[-1], clicks_s[-1] if len(clicks_s) else 0.0))
    steps = np.arange(_SUBDIVISIONS)
    fine = np.concatenate(
        (
            (grid[:-1, None] + np.diff(grid)[:, None] * steps[None, :] / _SUBDIVISIONS).ravel(),
            grid[-1:],
        )
    )

    sums = summed_envelope(fine, starts, ends, attacks, releases, levels, weights)
    level = _sides(sums[0], sums[1])
    weighted = _sides(sums[2], sums[3])
    sounding = level > SOUNDING
    sharp = np.where(sounding, weighted / np.where(sounding, level, 1.0), np.nan)
    last = np.maximum.accumulate(np.where(np.isnan(sharp), -1, np.arange(len(sharp))))
    last_sharpness = np.where(last >= 0, sharp[np.maximum(last, 0)], 0.5)
    times = np.repeat(fine, 2)
    value_a = np.minimum(1.0, np.where(sounding, level, 0.0)) * np.clip(
        _sides(intensity.at(fine, left=True), intensity.at(fine, left=False)), 0.0, 1.0
    )
    value_f = np.clip(
        last_sharpness + _sides(sharpness.at(fine, left=True), sharpness.at(fine, left=False)),
        0.0,
        1.0,
    )
    # Plain dicts, validated at once by the clip's model (one pass in pydantic-core).
    clicks = [
        {
            "t_s": float(e.Time),
            "amplitude": _unit(e.value("HapticIntensity", 1.0)) * _unit(float(control_i)),
            "frequency": _unit(e.value("HapticSharpness", 0.5) + float(control_s)),
        }
        for e, control_i, control_s in zip(
            sorted(transients, key=lambda e: e.Time),
            intensity.at(clicks_s, left=False),
            sharpness.at(clicks_s, left=False),
            strict=True,
        )
    ]
    return HapticClip.model_validate(
        {
            "duration_s": end_s if end_s > 0.0 else _EMPTY_S,
            "amplitude": _breakpoints(times, value_a, "amplitude"),
            "frequency": _breakpoints(times, value_f, "frequency"),
            "transients": clicks,
        }
    )


def _unit(value: float) -> float:
    return min(1.0, max(0.0, value))


def _sides(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Each grid time's two sides in a row: left, right, left, right, ..."""
    return np.stack((left, right), axis=1).ravel()


def _breakpoints(times: np.ndarray, values: np.ndarray, field: str) -> list[dict[str, float]]:
    """The breakpoints that draw ``values``; they are rounded to :data:`DIGITS` decimals
    first, so that sums equal but for rounding form one flat run."""
    values = np.round(values, DIGITS)
    kept = kept_points(times, values)
    if len(kept) > MAX_CLIP_POINTS:
        raise ParameterError(
            f"{field}: the events make {len(kept)} breakpoints; a clip may have "
            f"{MAX_CLIP_POINTS} (max_clip_points)"
        )
    return [
        {"t_s": t_s, "value": value}
        for t_s, value in zip(times[kept].tolist(), values[kept].tolist(), strict=True)
    ]


def _control(parameter: str, intensity: Control, sharpness: Control) -> Control | None:
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
