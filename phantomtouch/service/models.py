"""Request and response bodies of the REST API (and the touch request of ``play``).

A *touch request* has three shapes, told apart by their keys: a whole ``TouchPattern``
(``path`` ...), a preset with optional ``overrides`` (``preset``), or a stored pattern
(``stored``: its name in the library). Each may carry ``start_in_ms`` or ``start_at_s``.

``pattern`` is the deprecated name of ``stored`` (protocol 1 as first published): it is
still accepted, marked ``deprecated`` in the OpenAPI schema, and answered exactly as
``stored``; ``stored`` and ``pattern`` together are refused.
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
from phantomtouch.schema.pattern import TIMING_RULES, not_both

PATTERN_NAME_REGEX = (
    r"^(?:[A-Za-z0-9_-][A-Za-z0-9._-]{0,63}"
    r"|\.[A-Za-z0-9_-][A-Za-z0-9._-]{0,62}"
    r"|\.\.[A-Za-z0-9._-]{1,62})$"
)
"""1 to 64 letters, digits, '.', '_' and '-', except '.' and '..': clients that normalise
URLs turn ``/patterns/..`` into ``/``, so such a name could never be reached. (Written
without look-ahead, which pydantic's regex engine lacks.)"""


def name_rules(regex: str, example: str) -> dict[str, Any]:
    """The constraints of a stored pattern's or clip's name (``regex``), as keywords of
    pydantic's ``Field`` or FastAPI's ``Path``."""
    return {
        "min_length": 1,
        "max_length": 64,
        "pattern": regex,
        "description": "Letters, digits, '.', '_' and '-'; 1 to 64 characters; not '.' or '..'.",
        "examples": [example],
    }


PatternName = Annotated[str, Field(**name_rules(PATTERN_NAME_REGEX, "my-stroke"))]
MAX_START_IN_MS = 60_000.0
MAX_START_AHEAD_S = 3600.0
"""Latest start on the server clock, seconds from now."""


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


_NOT_BOTH_STARTS: JsonDict = not_both("start_in_ms", "start_at_s")


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
            "allOf": [_NOT_BOTH_STARTS, *TIMING_RULES],
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
    __config__=ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            "allOf": [not_both("speed_cm_s", "duration_s"), not_both("level_db", "intensity")]
        },
    ),
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
        json_schema_extra={**_NOT_BOTH_STARTS, "examples": [{"stored": "my-stroke"}]},
    )

    stored: PatternName


class LegacyNamedTouch(Timing):
    """Deprecated: ``pattern`` is the old name of ``stored`` (a :class:`NamedTouch`)."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            **_NOT_BOTH_STARTS,
            "deprecated": True,
            "examples": [{"pattern": "my-stroke"}],
        },
    )

    pattern: PatternName = Field(
        description="Deprecated name of `stored`: the name of a stored pattern."
    )

    def named(self) -> NamedTouch:
        """The same request in the current words."""
        return NamedTouch(
            stored=self.pattern, start_in_ms=self.start_in_ms, start_at_s=self.start_at_s
        )


_TOUCH_TAGS: dict[type[BaseModel], str] = {
    PresetTouch: "preset",
    NamedTouch: "named",
    LegacyNamedTouch: "legacy",
    PatternTouch: "touch",
}
"""The tag of each touch request model in :data:`TouchRequest`."""


def _touch_kind(data: Any) -> str | None:
    if isinstance(data, dict):
        if "preset" in data:
            return "preset"
        if "stored" in data:
            return "named"
        return "legacy" if "pattern" in data and "path" not in data else "touch"
    return next((tag for model, tag in _TOUCH_TAGS.items() if isinstance(data, model)), None)


TouchRequest = Annotated[
    Annotated[PatternTouch, Tag(_TOUCH_TAGS[PatternTouch])]
    | Annotated[PresetTouch, Tag(_TOUCH_TAGS[PresetTouch])]
    | Annotated[NamedTouch, Tag(_TOUCH_TAGS[NamedTouch])]
    | Annotated[LegacyNamedTouch, Tag(_TOUCH_TAGS[LegacyNamedTouch])],
    Discriminator(
        _touch_kind,
        custom_error_type="invalid_touch",
        custom_error_message=(
            "expected an object: a TouchPattern (with path), a preset (with preset) "
            "or a stored pattern (with stored)"
        ),
    ),
]
WireTouch = PatternTouch | PresetTouch | NamedTouch | LegacyNamedTouch
"""A touch request as the wire may phrase it."""
AnyTouch = PatternTouch | PresetTouch | NamedTouch
"""A touch request in the current words (a deprecated ``pattern`` is a ``stored`` by then)."""
touch_request_adapter: TypeAdapter[WireTouch] = TypeAdapter(TouchRequest)


def current_words(request: WireTouch) -> AnyTouch:
    """The request with a deprecated ``pattern`` renamed ``stored``."""
    return request.named() if isinstance(request, LegacyNamedTouch) else request


def parse_touch_request(body: str | bytes) -> AnyTouch:
    """A touch request from JSON text, strictly validated, in the current words.

    Raises
    ------
    pydantic.ValidationError
        The body is not one of the three shapes, or a field is out of range.
    """
    return current_words(touch_request_adapter.validate_json(body, strict=True))


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
    clipped_fraction: float | None = Field(
        default=None,
        ge=0.0,
        le=1.0,
        description=(
            "Estimated fraction of the frames in which a channel reaches the safety ceiling "
            "and is clipped, the pattern played alone (0: nothing clips; null: a pattern "
            "stored before the estimate existed)."
        ),
    )


class JobAccepted(BaseModel):
    """A touch scheduled on the engine."""

    job_id: str
    start_at_s: float = Field(description="Server time of the first sample, s.")
    start_frame: int
    duration_s: float
    path_length_cm: float
    speed_cm_s: float
    frames: int
    clipped_fraction: float = Field(
        ge=0.0,
        le=1.0,
        description="Estimated fraction of the frames clipped at the safety ceiling.",
    )

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
                    "clipped_fraction": 0.0,
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
    reason: str | None = Field(
        default=None,
        description="Why a stopped job stopped unasked: `stolen` (room for another), "
        "`closed` (the WebSocket connection that played it closed), or the engine's "
        "fault (`engine gone before it played`, `engine stalled while it "
        "played`: accepted just before the fault was noticed).",
    )


class StopAnswer(BaseModel):
    stopped: Literal[True] = True
    server_time_s: float
    frames: int
    """The engine's sample frame when the stop was applied (what a capture output recorded
    before it)."""


class PatternInfo(BaseModel):
    name: str
    summary: PlanSummary


class ClipInfo(BaseModel):
    """A clip of the library: its name and size."""

    name: str
    duration_s: float
    amplitude_points: int
    frequency_points: int
    transients: int


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
    block_frames: int = Field(
        description=(
            "Frames the engine renders at a time: the sound card's period, or a fixed "
            "divisor of it asked for with `--period`."
        )
    )
    period_frames: int = Field(
        description=(
            "Frames of each audio callback: the sound card's period (its playing time is "
            "the callback's budget, against which `render_load` is measured)."
        )
    )
    period_source: Literal["backend", "option", "profile"] = Field(
        description=(
            "Where the period came from: `backend` (JACK's server period, or the buffer "
            "ASIO, Core Audio or WASAPI reports), `option` (`--period`), or `profile` (the "
            "device profile's `block_frames`, for an output without a period of its own: "
            "the null and capture outputs, other host APIs)."
        )
    )
    output_latency_s: float
    actuators: list[Actuator]
    triangles: list[tuple[int, int, int]]
    max_level_db: float = Field(
        description=(
            "The device's safety.max_level_db: the strongest acceleration level, dB re "
            "1 µm/s², a touch may ask for (`level_db`; relative intensity 1 is this level)."
        )
    )


class ClockInfo(BaseModel):
    server_time_s: float = Field(description="The server's monotonic clock, s.")
    frames: int = Field(description="Frames the engine has played since it started.")
    sample_rate_hz: int
    unix_time_s: float


class InputState(BaseModel):
    """One supervised input (``osc``): ``running`` or ``restarting``."""

    state: str = Field(description="running, or restarting after its thread died")
    restarts: int = Field(description="Times its thread died and was started again.")
    last_failure: str | None = Field(default=None, description="What killed it last.")


class Health(BaseModel):
    """``ok``; or ``degraded`` with the part that fails named (the service still runs):
    ``engine`` while the engine process is being restarted, ``storage`` when the pattern
    store fails, ``degraded_inputs`` while an input is down or was just restarted."""

    status: Literal["ok", "degraded"] = "ok"
    backend: str
    engine: str = Field(
        description="running, starting, stalled, gone, restarting or closed",
    )
    underruns: int = Field(description="Audio blocks the sound card missed since start.")
    render_load_p99: float = Field(
        description="p99 of the audio callback's time per block over its playing time."
    )
    storage: str | None = Field(
        default=None, description="Why the pattern store fails (only when it does)."
    )
    inputs: dict[str, InputState] | None = Field(
        default=None, description="Supervised inputs (the OSC bridge), when any runs."
    )
    degraded_inputs: list[str] | None = Field(
        default=None,
        description="Inputs down, or restarted within the last minute (only when any is).",
    )
    wearer: str | None = Field(
        default=None,
        description="The wearer profile the output stage applies (only when there is one).",
    )
    wearer_band: str | None = Field(
        default=None, description="The carrier band of that profile the output stage applies."
    )


class Curves(BaseModel):
    """Control-rate view of a plan (the paper's Fig. 3), at most 500 points."""

    times_s: list[float]
    positions_cm: list[tuple[float, float]]
    gains: list[list[float]] = Field(description="Per channel, envelope included.")


class RenderPlan(PlanSummary):
    curves: Curves
