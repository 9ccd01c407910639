"""What an ``.ahap`` document may hold, checked in one pass of pydantic-core.

The parts of the file a clip is made of, as typed dictionaries rather than models: the
JSON bytes are validated straight into plain dicts, lists and floats
(:data:`AHAP_FILE`'s ``validate_json``), with no Python object per event, so the check
takes time linear in the file at a small multiple of ``json.loads``. Keys not listed
here are ignored. :mod:`~phantomtouch.clips.ahap` makes the clip of what this returns.
"""

from __future__ import annotations

from typing import Annotated, Literal, NotRequired

from pydantic import AfterValidator, Field, TypeAdapter
from typing_extensions import TypedDict

from phantomtouch.schema.clip import MAX_CLIP_POINTS, ClipTime

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
ControlValue = Annotated[float, Field(ge=-1.0, le=1.0, allow_inf_nan=False)]
"""A dynamic parameter's value, -1 to 1 (``HapticIntensityControl``: 0 to 1)."""

RANGES: dict[str, tuple[float, float]] = {
    "HapticIntensity": (0.0, 1.0),
    "HapticSharpness": (0.0, 1.0),
    "AttackTime": (0.0, 1.0),
    "DecayTime": (0.0, 1.0),
    "ReleaseTime": (0.0, 1.0),
    "Sustained": (0.0, 1.0),
    "AudioVolume": (0.0, 1.0),
    "AudioPan": (-1.0, 1.0),
    "AudioPitch": (-1.0, 1.0),
    "AudioBrightness": (0.0, 1.0),
    "HapticIntensityControl": (0.0, 1.0),
}
"""Apple's documented range of each parameter (Core Haptics, ``CHHapticParameter.h``);
every other dynamic parameter is -1 to 1. A value outside is refused, not clamped."""


def _in_range(parameter: str, value: float) -> None:
    low, high = RANGES.get(parameter, (-1.0, 1.0))
    if not low <= value <= high:
        raise ValueError(
            f"ParameterValue={value!r} is outside {parameter}'s range {low:g} to {high:g} "
            "(Apple's documented range)"
        )


class EventParameter(TypedDict):
    ParameterID: EventParameterId
    ParameterValue: Annotated[float, Field(allow_inf_nan=False)]


def _event_parameter(parameter: EventParameter) -> EventParameter:
    _in_range(parameter["ParameterID"], parameter["ParameterValue"])
    return parameter


class AhapEvent(TypedDict):
    Time: ClipTime
    EventType: Literal["HapticTransient", "HapticContinuous", "AudioContinuous", "AudioCustom"]
    EventDuration: NotRequired[
        Annotated[float, Field(gt=0.0, le=600.0, allow_inf_nan=False)] | None
    ]
    EventParameters: NotRequired[
        Annotated[
            list[Annotated[EventParameter, AfterValidator(_event_parameter)]],
            Field(max_length=16),
        ]
    ]


def _duration(event: AhapEvent) -> AhapEvent:
    if event["EventType"] == "HapticContinuous" and event.get("EventDuration") is None:
        raise ValueError("EventDuration is required for a HapticContinuous event")
    return event


class AhapParameter(TypedDict):
    ParameterID: DynamicParameterId
    Time: ClipTime
    ParameterValue: ControlValue


def _parameter(parameter: AhapParameter) -> AhapParameter:
    _in_range(parameter["ParameterID"], parameter["ParameterValue"])
    return parameter


class ControlPoint(TypedDict):
    Time: ClipTime
    ParameterValue: ControlValue


class AhapCurve(TypedDict):
    ParameterID: DynamicParameterId
    Time: ClipTime
    ParameterCurveControlPoints: Annotated[
        list[ControlPoint], Field(min_length=1, max_length=16_384)
    ]


def _increasing(curve: AhapCurve) -> AhapCurve:
    points = curve["ParameterCurveControlPoints"]
    for i, point in enumerate(points):
        try:
            _in_range(curve["ParameterID"], point["ParameterValue"])
        except ValueError as exc:
            raise ValueError(f"ParameterCurveControlPoints[{i}].{exc}") from None
    for i in range(1, len(points)):
        if points[i]["Time"] < points[i - 1]["Time"]:
            raise ValueError(
                f"ParameterCurveControlPoints[{i}].Time={points[i]['Time']!r} is before the "
                "point ahead of it; times never decrease"
            )
    return curve


class Entry(TypedDict):
    Event: NotRequired[Annotated[AhapEvent, AfterValidator(_duration)] | None]
    Parameter: NotRequired[Annotated[AhapParameter, AfterValidator(_parameter)] | None]
    ParameterCurve: NotRequired[Annotated[AhapCurve, AfterValidator(_increasing)] | None]


_KINDS = ("Event", "Parameter", "ParameterCurve")


def _one(entry: Entry) -> Entry:
    given = [name for name in _KINDS if entry.get(name) is not None]
    if len(given) != 1:
        raise ValueError(
            "each Pattern entry holds exactly one of Event, Parameter or ParameterCurve; "
            f"got {given or 'none'}"
        )
    return entry


class AhapFile(TypedDict):
    """The parts of an ``.ahap`` document a clip is made of."""

    Version: NotRequired[float | None]
    Pattern: Annotated[
        list[Annotated[Entry, AfterValidator(_one)]],
        Field(min_length=1, max_length=MAX_CLIP_POINTS),
    ]


AHAP_FILE: TypeAdapter[AhapFile] = TypeAdapter(AhapFile)
"""Validates an ``.ahap`` document: ``validate_json`` (bytes) or ``validate_python``."""
