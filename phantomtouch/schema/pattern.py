"""TouchPattern: one touch on the forearm described by its parameters.

A pattern is a path on the skin (cm), how fast it is travelled, fades, a carrier signal,
an intensity, an optional amplitude modulation, and the interpolation law and mode of
Kirchner et al. (IEEE ToH 2023, sec. III-A). Validation only: the renderer resolves it.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Self

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StrictInt, model_validator
from pydantic.config import JsonValue

from phantomtouch.schema import limits
from phantomtouch.schema.clip import ClipCarrier
from phantomtouch.schema.device import LevelDb

Coordinate = Annotated[
    float, Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM, allow_inf_nan=False)
]
Point = tuple[Coordinate, Coordinate]
"""A point on the skin: (x_cm, y_cm)."""


def _whole_number(value: Any) -> Any:
    """A JSON number without a fraction (``3.0``) as the integer it is in JSON Schema."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


JsonInt = Annotated[int, BeforeValidator(_whole_number)]
"""An integer as JSON Schema counts them: ``3`` and ``3.0`` alike (even when strict)."""
StrictJsonInt = Annotated[StrictInt, BeforeValidator(_whole_number)]
"""The same in a model that is not strict: ``3`` and ``3.0``, never ``"3"`` or ``true``."""

Law = Literal["linear", "log", "power"]
Mode = Literal["1d", "2d"]
Outside = Literal["project", "error"]
IntensityPreset = Literal["low", "high"]
RelativeIntensity = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]

_MAX_CARRIER_HZ = limits.MAX_SAMPLE_RATE_HZ / 2
_MAX_MODULATION_HZ = 1000.0


def _kind_required(schema: dict[str, Any]) -> None:
    """A discriminated variant's ``kind`` is required on the wire, its default aside."""
    if "kind" in schema.get("properties", {}):
        schema["required"] = ["kind", *schema.get("required", [])]


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", json_schema_extra=_kind_required)


class PolylinePath(_Model):
    """Straight segments through the points, travelled at constant speed."""

    kind: Literal["polyline"] = "polyline"
    points_cm: list[Point] = Field(
        min_length=1,
        max_length=limits.MAX_PATH_POINTS,
        fail_fast=True,
        description="Points (x_cm, y_cm); one point is a touch that does not move.",
    )


class ArcPath(_Model):
    """The circular arc from `start_cm` through `through_cm` to `end_cm`."""

    kind: Literal["arc"] = "arc"
    start_cm: Point
    through_cm: Point
    end_cm: Point


class SplinePath(_Model):
    """A smooth curve (natural cubic spline, chord-length parameter) through the points."""

    kind: Literal["spline"] = "spline"
    points_cm: list[Point] = Field(min_length=2, max_length=limits.MAX_PATH_POINTS, fail_fast=True)


class Keyframe(_Model):
    """Where the point is at time `t_s` after the fade-in; positions between are linear."""

    t_s: float = Field(ge=0.0, le=limits.MAX_DURATION_S, allow_inf_nan=False)
    x_cm: Coordinate
    y_cm: Coordinate
    intensity: float = Field(
        default=1.0, ge=0.0, le=1.0, description="Factor on the pattern's amplitude."
    )


class KeyframePath(_Model):
    """Timed keyframes: variable speed, pauses and full stops."""

    kind: Literal["keyframes"] = "keyframes"
    keyframes: list[Keyframe] = Field(
        min_length=1, max_length=limits.MAX_PATH_POINTS, fail_fast=True
    )

    @model_validator(mode="after")
    def _increasing(self) -> Self:
        times = [k.t_s for k in self.keyframes]
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise ValueError(
                    f"keyframes[{i}].t_s={times[i]!r} must be greater than "
                    f"keyframes[{i - 1}].t_s={times[i - 1]!r} (times strictly increase)"
                )
        return self


PathSpec = Annotated[
    PolylinePath | ArcPath | SplinePath | KeyframePath, Field(discriminator="kind")
]


class SineCarrier(_Model):
    """A sine at `freq_hz`."""

    kind: Literal["sine"] = "sine"
    freq_hz: float = Field(
        default=100.0, ge=limits.MIN_CARRIER_HZ, lt=_MAX_CARRIER_HZ, allow_inf_nan=False
    )


class _Band(_Model):
    low_hz: float = Field(
        default=40.0, ge=limits.MIN_NOISE_BAND_HZ, lt=_MAX_CARRIER_HZ, allow_inf_nan=False
    )
    high_hz: float = Field(default=500.0, gt=0.0, lt=_MAX_CARRIER_HZ, allow_inf_nan=False)
    seed: JsonInt = Field(default=0, ge=0, le=limits.MAX_SEED, description="Noise seed.")

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        if self.high_hz <= self.low_hz * 1.05:
            raise ValueError(
                f"high_hz={self.high_hz!r} must be at least 5 % above low_hz={self.low_hz!r}"
            )
        return self


class NoiseCarrier(_Band):
    """Band-limited white noise, RMS equal to a unit sine's (1/sqrt(2))."""

    kind: Literal["noise"] = "noise"


class CombinedCarrier(_Band):
    """Sine plus noise of equal RMS, the sum scaled back to the sine's RMS (the paper's)."""

    kind: Literal["combined"] = "combined"
    freq_hz: float = Field(
        default=100.0, ge=limits.MIN_CARRIER_HZ, lt=_MAX_CARRIER_HZ, allow_inf_nan=False
    )


Carrier = Annotated[SineCarrier | NoiseCarrier | CombinedCarrier, Field(discriminator="kind")]
"""A carrier a live contact can play: a steady signal."""
PatternCarrier = Annotated[
    SineCarrier | NoiseCarrier | CombinedCarrier | ClipCarrier, Field(discriminator="kind")
]
"""A pattern's carrier: a steady signal, or a haptic clip with its own envelope."""


def given(name: str, schema: dict[str, Any] | None = None) -> dict[str, Any]:
    """JSON Schema: ``name`` is present and not null (``schema``: and matches it)."""
    return {"required": [name], "properties": {name: schema or {"not": {"type": "null"}}}}


def not_both(first: str, second: str) -> dict[str, Any]:
    """JSON Schema: ``first`` and ``second`` are not both given (null counts as absent)."""
    return {"not": {"allOf": [given(first), given(second)]}}


TIMING_RULES: list[JsonValue] = [
    not_both("intensity", "level_db"),
    {
        # A keyframe path carries its own times; any other path takes exactly one of
        # speed_cm_s or duration_s.
        "if": {
            "required": ["path"],
            "properties": {
                "path": {"required": ["kind"], "properties": {"kind": {"const": "keyframes"}}}
            },
        },
        "then": {"not": {"anyOf": [given("speed_cm_s"), given("duration_s")]}},
        "else": {"oneOf": [given("speed_cm_s"), given("duration_s")]},
    },
]
"""The cross-field rules of :class:`TouchPattern`'s ``_timing`` as JSON Schema."""


class AmplitudeModulation(_Model):
    """Eq. 2: ``a(t) * ((1 - m/2) - (m/2) cos(2 pi f_m t))``.

    With ``freq_hz="stroke"`` one period spans each stroke (fades included), so the
    amplitude is 0 at the stroke's start and end and full in its middle.
    """

    index: float = Field(default=1.0, ge=0.0, le=1.0, description="Modulation index m.")
    freq_hz: float | Literal["stroke"] = Field(
        default="stroke",
        description="Modulation frequency f_m in Hz (0 < f_m <= 1000), or 'stroke'.",
        json_schema_extra={
            "anyOf": [
                {"type": "number", "exclusiveMinimum": 0.0, "maximum": _MAX_MODULATION_HZ},
                {"const": "stroke", "type": "string"},
            ]
        },
    )

    @model_validator(mode="after")
    def _frequency(self) -> Self:
        if self.freq_hz != "stroke" and not 0.0 < float(self.freq_hz) <= _MAX_MODULATION_HZ:
            raise ValueError(
                f"freq_hz={self.freq_hz!r} must be > 0 and <= {_MAX_MODULATION_HZ:g} Hz, "
                "or 'stroke'"
            )
        return self


class TouchPattern(_Model):
    """A touch: path, timing, carrier, intensity, modulation, interpolation.

    Give either ``speed_cm_s`` (eq. 1: duration = fade-in + length / speed + fade-out) or
    ``duration_s`` (the whole pattern, fades and every stroke included); keyframe paths
    carry their own timing and take neither.
    """

    model_config = ConfigDict(
        frozen=True,
        extra="forbid",
        json_schema_extra={
            "allOf": TIMING_RULES,
            "examples": [
                {
                    "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
                    "speed_cm_s": 5.0,
                    "carrier": {"kind": "sine", "freq_hz": 100.0},
                    "intensity": "low",
                }
            ],
        },
    )

    path: PathSpec
    speed_cm_s: float | None = Field(
        default=None,
        gt=limits.MIN_SPEED_CM_S,
        le=limits.MAX_SPEED_CM_S,
        allow_inf_nan=False,
        description="Constant speed along the path, cm/s.",
    )
    duration_s: float | None = Field(
        default=None,
        gt=0.0,
        le=limits.MAX_DURATION_S,
        allow_inf_nan=False,
        description="Total duration of the pattern (all strokes and fades), s.",
    )
    fade_in_s: float = Field(default=0.6, ge=0.0, le=limits.MAX_FADE_S, allow_inf_nan=False)
    fade_out_s: float = Field(default=0.6, ge=0.0, le=limits.MAX_FADE_S, allow_inf_nan=False)
    repeat: JsonInt = Field(
        default=1, ge=1, le=limits.MAX_REPEAT, description="Strokes, each with its own fades."
    )
    alternate: bool = Field(default=False, description="Every second stroke runs backwards.")
    carrier: PatternCarrier = Field(default_factory=SineCarrier)
    intensity: RelativeIntensity | IntensityPreset = Field(
        default="low",
        description=(
            "Relative amplitude 0-1 (1 = the device's max_level_db), or 'low' / 'high': "
            "the paper's Table I level for the carrier."
        ),
    )
    level_db: LevelDb | None = Field(
        default=None,
        description="Acceleration level, dB re 1 µm/s² (RMS); replaces `intensity`.",
    )
    modulation: AmplitudeModulation | None = None
    law: Law = Field(default="power", description="Interpolation law between actuators.")
    mode: Mode = Field(default="2d", description="'2d' barycentric, or '1d' along y only.")
    outside: Outside = Field(
        default="project",
        description="Points outside the actuator hull: project onto it, or refuse.",
    )

    @model_validator(mode="after")
    def _timing(self) -> Self:
        if self.level_db is not None and "intensity" in self.model_fields_set:
            raise ValueError("give either intensity or level_db, not both")
        given = [n for n in ("speed_cm_s", "duration_s") if getattr(self, n) is not None]
        if isinstance(self.path, KeyframePath):
            if given:
                raise ValueError(f"{given[0]} does not apply to a keyframe path (its times do)")
        elif len(given) != 1:
            raise ValueError(
                "give exactly one of speed_cm_s or duration_s"
                + (f" (got both: {self.speed_cm_s!r}, {self.duration_s!r})" if given else "")
            )
        return self
