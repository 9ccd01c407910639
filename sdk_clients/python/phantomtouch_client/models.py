"""What the server answers, and the one builder of touch requests.

Patterns are :class:`~phantomtouch_client.pattern.TouchPattern`, validated here before
they are sent, so a bad pattern fails in the caller's process with the message the server would
give. Answers are parsed into the small models below; they accept fields a newer server
adds (``extra="allow"``), so a client keeps working across server versions.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal, TypeAlias

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from phantomtouch_client.errors import InvalidRequest, ParameterError
from phantomtouch_client.pattern import TouchPattern

JobState = Literal["scheduled", "playing", "finished", "stopped"]
JobId: TypeAlias = str
PatternArg: TypeAlias = TouchPattern | Mapping[str, Any] | None
"""A pattern argument: a :class:`TouchPattern`, its JSON, or ``None``."""


class _Answer(BaseModel):
    model_config = ConfigDict(extra="allow", frozen=True)


class Job(_Answer):
    """A scheduled touch: the answer to ``POST /touch``, a pattern's play and WS ``play``."""

    job_id: JobId
    start_at_s: float = Field(description="Start on the server clock, s.")
    start_frame: int
    duration_s: float
    path_length_cm: float
    speed_cm_s: float
    frames: int
    clipped_fraction: float = Field(
        description="Estimated fraction of the frames clipped at the safety ceiling."
    )


class JobStatus(_Answer):
    """``GET /jobs/{id}`` and ``DELETE /jobs/{id}``."""

    job_id: JobId
    state: JobState
    start_at_s: float
    start_frame: int
    end_at_s: float
    end_frame: int
    duration_s: float
    late: bool
    """Whether the job started after the time it was asked for."""
    reason: str | None = None
    """Why a ``stopped`` job stopped when no one asked it to (``stolen``, or the engine's
    fault, e.g. ``engine gone before it played``); None otherwise."""


class StopAnswer(_Answer):
    """``POST /stop``."""

    server_time_s: float
    frames: int | None = None
    """The engine's sample frame when the stop was applied (None from an older server)."""
    stopped: bool = True


class PlanSummary(_Answer):
    """What a pattern resolves to (the renderer's plan): timing, path, level."""

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
    clipped_fraction: float | None = None
    """Estimated fraction of the frames clipped at the safety ceiling (0: none; None: a
    pattern stored before the server gave the estimate)."""


class Summary(_Answer):
    """One stored pattern or preset: its name and its plan's summary."""

    name: str
    summary: PlanSummary


class ClipSummary(_Answer):
    """One stored haptic clip: its name, length and size."""

    name: str
    duration_s: float
    amplitude_points: int
    frequency_points: int
    transients: int


class TactSummary(_Answer):
    """One stored bHaptics ``.tact`` project: its name, size, length and positions."""

    name: str
    bytes: int
    duration_s: float
    positions: list[str]
    effects: int


class WorkspaceSummary(_Answer):
    """One stored bHaptics SDK2 workspace: a game's deployment, summarised."""

    workspace_id: str
    game: str
    version: int | None
    bytes: int
    events: int
    arm_events: int
    longest_ms: int


class ScoreStarted(_Answer):
    """A stored ``.tact`` project scheduled: one job per voice, from ``start_frame``."""

    name: str
    job_ids: list[str]
    start_at_s: float
    start_frame: int
    duration_s: float


class RenderCurves(_Answer):
    """At most 500 points of a rendered touch; ``gains`` include the envelope."""

    times_s: list[float]
    positions_cm: list[tuple[float, float]]
    gains: list[list[float]]


class RenderPlan(PlanSummary):
    """``POST /render`` with ``Accept: application/json``: the plan and its curves."""

    curves: RenderCurves


class Clock(_Answer):
    """``GET /clock``: the server's sample clock and wall clock."""

    server_time_s: float
    frames: int
    sample_rate_hz: int
    unix_time_s: float


class InputState(_Answer):
    """One supervised input of ``GET /health`` (``osc``)."""

    state: str
    """``running``, or ``restarting`` after its thread died."""
    restarts: int
    last_failure: str | None = None


class Health(_Answer):
    """``GET /health``: ``degraded`` while the service's engine is being restarted, with
    ``storage`` saying why the pattern store fails, or naming ``degraded_inputs``."""

    status: Literal["ok", "degraded"] = "ok"
    backend: str
    engine: str
    underruns: int
    render_load_p99: float
    storage: str | None = None
    inputs: dict[str, InputState] | None = None
    """Supervised inputs (the OSC bridge), when any runs."""
    degraded_inputs: list[str] | None = None
    """Inputs down, or restarted within the last minute."""
    wearer: str | None = None
    """The wearer profile the output stage applies now, if any."""
    wearer_band: str | None = None


class ActiveWearer(_Answer):
    """``GET|PUT /wearer``: the wearer the output stage is fitted to (``name`` and
    ``band`` None: none) and the offset it applies per output channel, dB (index 0 is
    channel 1)."""

    name: str | None = None
    band: str | None = None
    offsets_db: list[float] = []


class Wearer(_Answer):
    """A wearer profile: per band (``sine_100hz``, ``noise_40_500hz``) and actuator
    (output channel, 1-based, a string key) an offset in dB, within ±20 dB."""

    offsets_db: dict[str, dict[str, float]] = {}
    note: str = ""


class WearerRun(_Answer):
    """``GET|PUT /wearers/{name}/run``: the answers of a wearer's matching run so far, in
    the band ``band`` against the reference actuator on ``reference_channel``; each trial
    a dict ``{"channel", "level_db", "test_stronger"}`` (``level_db`` re the reference)."""

    band: str
    reference_channel: int
    trials: list[dict[str, Any]] = []


class WearerSummary(_Answer):
    """One entry of ``GET /wearers``."""

    name: str
    active: bool
    profile: Wearer


class DeviceInfo(_Answer):
    """``GET /device``: layout, channels, sample rate, block size, backend, output device."""

    name: str
    backend: str
    output_device: str | None
    channels: int
    sample_rate_hz: int
    block_frames: int
    period_frames: int | None = None
    """Frames of each audio callback, the sound card's period (None: an older server)."""
    period_source: str | None = None
    """``backend``, ``option`` (``--period``) or ``profile`` (None: an older server)."""
    output_latency_s: float
    actuators: list[dict[str, Any]]
    triangles: list[tuple[int, int, int]]
    max_level_db: float


class LaneOffer(_Answer):
    """The contact lane of a ``welcome``: a UDP ``port`` on the service's host (1-65535)
    and the connection's ``key`` (see :mod:`phantomtouch_client.lane`)."""

    port: int = Field(ge=1, le=65535)
    key: str = Field(min_length=1)


class Welcome(_Answer):
    """The server's answer to ``hello``."""

    protocol: int
    server_time_s: float
    watchdog_s: float
    device: dict[str, Any] = Field(default_factory=dict)
    wearer: dict[str, str] | None = None
    """The wearer the armband's output stage is fitted to (``{name, band}``), if any."""
    lane: LaneOffer | None = None
    """The contact lane this connection may send its moves over, if the service runs one."""


class ContactState(_Answer):
    """One live contact in a ``state`` message."""

    contact: str
    x_cm: float
    y_cm: float
    own: bool = False
    """Whether the contact is this connection's (the state lists every client's)."""


class State(_Answer):
    """A ``state`` message, pushed at the rate asked for with ``subscribe``."""

    server_time_s: float
    levels: list[float] = Field(default_factory=list)
    contacts: list[ContactState] = Field(default_factory=list)
    active_voices: int = 0
    underruns: int = 0
    output_latency_s: float | None = None


class Released(_Answer):
    """This connection's contacts that the server released: ``reason`` is ``watchdog``
    (the client went silent) or ``stop`` (a global stop)."""

    reason: str
    contacts: list[str] = Field(default_factory=list)


def _location(loc: tuple[int | str, ...]) -> str:
    parts: list[str] = []
    for item in loc:
        parts.append(f"[{item}]" if isinstance(item, int) else ("." if parts else "") + item)
    return "".join(parts) or "body"


def error_items(exc: ValidationError) -> list[dict[str, Any]]:
    """One dict per problem, as the server's ``fields``: ``field``, ``value``, ``message``."""
    return [
        {
            "field": _location(err["loc"]),
            "value": err.get("input"),
            "message": err["msg"].removeprefix("Value error, "),
        }
        for err in exc.errors(include_url=False)
    ]


def describe(fields: list[dict[str, Any]]) -> str:
    """``field=value: message`` for each problem, as the server words its refusals."""

    def short(value: Any) -> str:
        text = repr(value)
        return text if len(text) <= 80 else text[:77] + "..."

    return "; ".join(f"{f['field']}={short(f['value'])}: {f['message']}" for f in fields)


def pattern_json(pattern: TouchPattern | Mapping[str, Any]) -> dict[str, Any]:
    """A pattern as the JSON object the server reads, validated on the way.

    Raises :class:`InvalidRequest` (a ``ValueError``) naming each bad field.
    """
    if isinstance(pattern, BaseModel) and not isinstance(pattern, TouchPattern):
        # e.g. the service's own phantomtouch.TouchPattern: its JSON is the same
        pattern = pattern.model_dump(mode="json", exclude_unset=True)
    if not isinstance(pattern, TouchPattern):
        try:
            pattern = TouchPattern.model_validate(pattern)
        except ValidationError as exc:
            fields = error_items(exc)
            raise InvalidRequest(describe(fields), code="invalid", fields=fields) from exc
    body: dict[str, Any] = pattern.model_dump(mode="json", exclude_unset=True)
    return body


def contact_message(kind: str, contact: str, **fields: Any) -> dict[str, Any]:
    """A ``down``, ``move`` or ``up`` message; fields that are None are left out."""
    message: dict[str, Any] = {"type": kind, "contact": contact}
    message.update({name: value for name, value in fields.items() if value is not None})
    return message


def touch_request(
    pattern: TouchPattern | Mapping[str, Any] | None = None,
    *,
    preset: str | None = None,
    stored: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    start_in_ms: float | None = None,
    start_at_s: float | None = None,
) -> dict[str, Any]:
    """The body of ``POST /touch``, ``POST /render`` and the WebSocket ``play``.

    Exactly one of ``pattern`` (a :class:`TouchPattern` or its JSON), ``preset`` (a preset
    name, with optional ``overrides`` of pattern fields) or ``stored`` (the name of a pattern
    stored with ``PUT /patterns/{name}``). At most one of ``start_in_ms`` (0-60000, from now)
    or ``start_at_s`` (on the server clock); neither means as soon as possible.
    """
    given = [
        name
        for name, value in (("pattern", pattern), ("preset", preset), ("stored", stored))
        if value is not None
    ]
    if len(given) != 1:
        raise ParameterError(
            f"give exactly one of pattern, preset or stored (got {', '.join(given) or 'none'})"
        )
    if overrides is not None and preset is None:
        raise ParameterError("overrides apply to a preset only")
    when = timing(start_in_ms=start_in_ms, start_at_s=start_at_s)
    if pattern is not None:
        body = pattern_json(pattern)
    elif preset is not None:
        body = {"preset": preset}
        if overrides:
            body["overrides"] = dict(overrides)
    else:
        body = {"stored": stored}
    body.update(when)
    return body


def fleet_touch_request(body: dict[str, Any], start_at_unix_s: float | None) -> dict[str, Any]:
    """A touch request for a fleet gateway: ``start_at_unix_s`` (wall clock, s) added.

    It may not go with ``start_in_ms`` or ``start_at_s`` (those are one armband's clock).
    """
    if start_at_unix_s is None:
        return body
    if "start_in_ms" in body or "start_at_s" in body:
        raise ParameterError(
            f"start_at_unix_s={start_at_unix_s!r}: give it or start_in_ms / start_at_s, not both"
        )
    return {**body, "start_at_unix_s": start_at_unix_s}


def timing(*, start_in_ms: float | None = None, start_at_s: float | None = None) -> dict[str, Any]:
    """The optional timing fields of a request."""
    if start_in_ms is not None and start_at_s is not None:
        raise ParameterError(
            f"give at most one of start_in_ms={start_in_ms!r} or start_at_s={start_at_s!r}"
        )
    if start_in_ms is not None:
        return {"start_in_ms": start_in_ms}
    if start_at_s is not None:
        return {"start_at_s": start_at_s}
    return {}
