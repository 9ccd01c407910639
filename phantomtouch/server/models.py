"""Request and response bodies of the REST API (and the touch request of ``play``).

A *touch request* has three shapes, told apart by their keys: a whole ``TouchPattern``
(``path`` ...), a preset with optional ``overrides`` (``preset``), or a stored pattern
(``pattern``). Each may carry ``start_in_ms`` or ``start_at_s``.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Self

from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    TypeAdapter,
    create_model,
    model_validator,
)
from pydantic.config import JsonDict

from phantomtouch.schema import TouchPattern
from phantomtouch.schema.device import Actuator

PATTERN_NAME_REGEX = r"^[A-Za-z0-9._-]{1,64}$"
PatternName = Annotated[
    str,
    Field(
        min_length=1,
        max_length=64,
        pattern=PATTERN_NAME_REGEX,
        description="Letters, digits, '.', '_' and '-'; 1 to 64 characters.",
        examples=["my-stroke"],
    ),
]
MAX_START_IN_MS = 60_000.0
MAX_START_AHEAD_S = 3600.0
"""Latest start on the server clock, seconds from now."""


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


_NOT_BOTH_STARTS: JsonDict = {
    "not": {
        "required": ["start_in_ms", "start_at_s"],
        "properties": {"start_in_ms": {"type": "number"}, "start_at_s": {"type": "number"}},
    }
}


class Timing(_Body):
    """When a touch starts: ``start_in_ms`` from now, or ``start_at_s`` on the server clock."""

    model_config = ConfigDict(json_schema_extra=_NOT_BOTH_STARTS)

    start_in_ms: float | None = Field(
        default=None,
        ge=0.0,
        le=MAX_START_IN_MS,
        allow_inf_nan=False,
        description="Start this many ms from now (0-60000).",
    )
    start_at_s: float | None = Field(
        default=None,
        ge=0.0,
        le=1e9,
        allow_inf_nan=False,
        description="Start at this server time (`GET /clock`), s; at most 3600 s ahead.",
    )

    @model_validator(mode="after")
    def _one_start(self) -> Self:
        if self.start_in_ms is not None and self.start_at_s is not None:
            raise ValueError(
                f"give start_in_ms ({self.start_in_ms!r}) or start_at_s ({self.start_at_s!r}), "
                "not both"
            )
        return self

    def timing(self) -> Timing:
        return Timing(start_in_ms=self.start_in_ms, start_at_s=self.start_at_s)


class PatternTouch(TouchPattern, Timing):
    """A whole ``TouchPattern``, plus optional timing."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            **_NOT_BOTH_STARTS,
            "examples": [
                {
                    "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
                    "speed_cm_s": 5.0,
                    "start_in_ms": 20.0,
                }
            ],
        },
    )

    def pattern(self) -> TouchPattern:
        data = self.model_dump(exclude={"start_in_ms", "start_at_s"}, exclude_unset=True)
        return TouchPattern.model_validate(data)


def _optional_fields() -> dict[str, Any]:
    fields: dict[str, Any] = {}
    for name, info in TouchPattern.model_fields.items():
        constraints = [*info.metadata]
        if info.discriminator is not None:
            constraints.append(Field(discriminator=info.discriminator))
        annotation: Any = (
            Annotated[info.annotation, *constraints] if constraints else info.annotation
        )
        fields[name] = (annotation | None, Field(default=None, description=info.description))
    return fields


PatternOverrides: type[BaseModel] = create_model(
    "PatternOverrides",
    __config__=ConfigDict(extra="forbid", frozen=True),
    __doc__=(
        "TouchPattern fields that replace the preset's. `speed_cm_s` replaces the preset's "
        "`duration_s` (and the other way round); `level_db` replaces `intensity`."
    ),
    **_optional_fields(),
)

_EXCLUSIVE = {
    "speed_cm_s": "duration_s",
    "duration_s": "speed_cm_s",
    "level_db": "intensity",
    "intensity": "level_db",
}


class PresetTouch(Timing):
    """A named preset (`GET /presets`), with optional overrides and timing."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            **_NOT_BOTH_STARTS,
            "examples": [{"preset": "exp2/curved", "overrides": {"intensity": "high"}}],
        },
    )

    preset: str = Field(min_length=1, max_length=100, examples=["exp2/curved"])
    overrides: PatternOverrides | None = None

    def apply(self, base: TouchPattern) -> TouchPattern:
        if self.overrides is None:
            return base
        changes = self.overrides.model_dump(exclude_unset=True, exclude_none=True)
        data = base.model_dump(exclude_unset=True)
        for name in changes:
            if name in _EXCLUSIVE:
                data.pop(_EXCLUSIVE[name], None)
        data.update(changes)
        return TouchPattern.model_validate(data)


class NamedTouch(Timing):
    """A pattern stored in the library (`GET /patterns`), with optional timing."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={**_NOT_BOTH_STARTS, "examples": [{"pattern": "my-stroke"}]},
    )

    pattern: PatternName


def _touch_kind(data: Any) -> str | None:
    if isinstance(data, dict):
        if "preset" in data:
            return "preset"
        return "named" if "pattern" in data else "touch"
    if isinstance(data, PresetTouch):
        return "preset"
    if isinstance(data, NamedTouch):
        return "named"
    return "touch" if isinstance(data, PatternTouch) else None


TouchRequest = Annotated[
    Annotated[PatternTouch, Tag("touch")]
    | Annotated[PresetTouch, Tag("preset")]
    | Annotated[NamedTouch, Tag("named")],
    Discriminator(
        _touch_kind,
        custom_error_type="invalid_touch",
        custom_error_message=(
            "expected an object: a TouchPattern (with path), a preset (with preset) "
            "or a stored pattern (with pattern)"
        ),
    ),
]
touch_request_adapter: TypeAdapter[PatternTouch | PresetTouch | NamedTouch] = TypeAdapter(
    TouchRequest
)


class PlayRequest(Timing):
    """Optional timing of `POST /patterns/{name}/play`."""


class PlanSummary(BaseModel):
    """A pattern resolved for the device (eq. 1 timing, level, layout fit)."""

    duration_s: float
    path_length_cm: float
    speed_cm_s: float
    frames: int
    channels: int
    sample_rate_hz: int
    strokes: int
    stroke_s: float
    motion_s: float
    level_db: float | None
    amplitude: float
    projected_points: int
    max_projection_cm: float


class JobAccepted(BaseModel):
    """A touch scheduled on the engine."""

    job_id: str
    start_at_s: float = Field(description="Server time of the first sample, s.")
    start_frame: int
    duration_s: float
    path_length_cm: float
    speed_cm_s: float
    frames: int

    model_config = {
        "json_schema_extra": {
            "examples": [
                {
                    "job_id": "17",
                    "start_at_s": 1234.52,
                    "start_frame": 59256960,
                    "duration_s": 3.12,
                    "path_length_cm": 9.6,
                    "speed_cm_s": 5.0,
                    "frames": 149760,
                }
            ]
        }
    }


JobStateName = Literal["scheduled", "playing", "finished", "stopped"]


class JobInfo(BaseModel):
    """Where a job is; times on the server clock."""

    job_id: str
    state: JobStateName
    start_at_s: float = Field(description="First sample (actual once started), s.")
    start_frame: int
    end_at_s: float = Field(description="From here on silent (after a stop: its release), s.")
    end_frame: int
    duration_s: float = Field(description="The pattern's duration, s.")
    late: bool = Field(description="It started after its requested start.")


class StopAnswer(BaseModel):
    stopped: Literal[True] = True
    server_time_s: float


class PatternInfo(BaseModel):
    name: str
    summary: PlanSummary


class PresetInfo(BaseModel):
    name: str
    summary: PlanSummary


class DeviceInfo(BaseModel):
    """The armband as the service drives it."""

    name: str
    backend: Literal["sounddevice", "null", "capture"]
    output_device: str | None
    channels: int
    sample_rate_hz: int
    block_frames: int
    output_latency_s: float
    actuators: list[Actuator]
    triangles: list[tuple[int, int, int]]


class ClockInfo(BaseModel):
    server_time_s: float = Field(description="The server's monotonic clock, s.")
    frames: int = Field(description="Frames the engine has played since it started.")
    sample_rate_hz: int
    unix_time_s: float


class Health(BaseModel):
    """``ok``; or ``degraded`` with the part that fails named (the service still runs)."""

    status: Literal["ok", "degraded"] = "ok"
    backend: str
    storage: str | None = Field(
        default=None, description="Why the pattern store fails (only when it does)."
    )


class Curves(BaseModel):
    """Control-rate view of a plan (the paper's Fig. 3), at most 500 points."""

    times_s: list[float]
    positions_cm: list[tuple[float, float]]
    gains: list[list[float]] = Field(description="Per channel, envelope included.")


class RenderPlan(PlanSummary):
    curves: Curves
