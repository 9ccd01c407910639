"""Every REST route as a plain description of one HTTP call, free of I/O.

:class:`~phantomtouch_client.Client` and :class:`~phantomtouch_client.AsyncClient` only
send these and hand the response to ``parse``, so both speak the routes the same way.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar
from urllib.parse import quote

import httpx
from pydantic import BaseModel, TypeAdapter, ValidationError

from phantomtouch_client.errors import TransportError, error_from_response
from phantomtouch_client.models import (
    ActiveWearer,
    ClipSummary,
    Clock,
    DeviceInfo,
    Health,
    Job,
    JobId,
    JobStatus,
    RenderPlan,
    ScoreStarted,
    StopAnswer,
    Summary,
    TactSummary,
    Wearer,
    WearerRun,
    WearerSummary,
    WorkspaceSummary,
    pattern_json,
    timing,
)
from phantomtouch_client.pattern import HapticClip, TouchPattern

T = TypeVar("T")
M = TypeVar("M", bound=BaseModel)


@dataclass(frozen=True)
class Call(Generic[T]):
    """One HTTP request and how to read its answer."""

    method: str
    path: str
    parse: Callable[[httpx.Response], T]
    body: Any = None
    accept: str = "application/json"
    params: Mapping[str, int] | None = None
    """The query string's parameters (``GET /tact``'s page), or None."""


def checked(response: httpx.Response) -> httpx.Response:
    """The response itself when it is a success, else the :class:`ApiError` it carries."""
    if response.is_success:
        return response
    try:
        body = response.json()
    except ValueError:
        body = None
    raise error_from_response(response.status_code, body, response.text)


def _decode(response: httpx.Response) -> Any:
    try:
        return checked(response).json()
    except json.JSONDecodeError as exc:
        raise TransportError(
            f"{response.request.method} {response.request.url.path}: the answer is not JSON"
        ) from exc


def _model(model: type[M]) -> Callable[[httpx.Response], M]:
    def parse(response: httpx.Response) -> M:
        data = _decode(response)
        try:
            return model.model_validate(data)
        except ValidationError as exc:
            raise TransportError(
                f"{response.request.url.path}: unexpected answer for {model.__name__}: {exc}"
            ) from exc

    return parse


_SUMMARIES = TypeAdapter(list[Summary])


def _summaries(response: httpx.Response) -> list[Summary]:
    try:
        return _SUMMARIES.validate_python(_decode(response))
    except ValidationError as exc:
        raise TransportError(f"{response.request.url.path}: unexpected answer: {exc}") from exc


_CLIP_SUMMARIES = TypeAdapter(list[ClipSummary])


def _clip_summaries(response: httpx.Response) -> list[ClipSummary]:
    try:
        return _CLIP_SUMMARIES.validate_python(_decode(response))
    except ValidationError as exc:
        raise TransportError(f"{response.request.url.path}: unexpected answer: {exc}") from exc


def _nothing(response: httpx.Response) -> None:
    checked(response)


def _bytes(response: httpx.Response) -> bytes:
    return checked(response).content


def _text(response: httpx.Response) -> str:
    return checked(response).text


def _segment(value: JobId) -> str:
    return quote(str(value), safe="")


def touch(body: dict[str, Any], armband: str | None = None) -> Call[Job]:
    if armband is None:
        return Call("POST", "/touch", _model(Job), body)
    return Call("POST", f"/armbands/{_segment(armband)}/touch", _model(Job), body)


def _records(response: httpx.Response) -> list[dict[str, Any]]:
    data = _decode(response)
    if not isinstance(data, list):
        raise TransportError(f"{response.request.url.path}: expected a list of armbands")
    return data


def armbands() -> Call[list[dict[str, Any]]]:
    return Call("GET", "/armbands", _records)


def render_wav(body: dict[str, Any]) -> Call[bytes]:
    return Call("POST", "/render", _bytes, body, accept="audio/wav")


def render_plan(body: dict[str, Any]) -> Call[RenderPlan]:
    return Call("POST", "/render", _model(RenderPlan), body)


def job(job_id: JobId) -> Call[JobStatus]:
    return Call("GET", f"/jobs/{_segment(job_id)}", _model(JobStatus))


def cancel_job(job_id: JobId) -> Call[JobStatus]:
    return Call("DELETE", f"/jobs/{_segment(job_id)}", _model(JobStatus))


def stop() -> Call[StopAnswer]:
    return Call("POST", "/stop", _model(StopAnswer))


def patterns() -> Call[list[Summary]]:
    return Call("GET", "/patterns", _summaries)


def get_pattern(name: str) -> Call[TouchPattern]:
    return Call("GET", f"/patterns/{_segment(name)}", _model(TouchPattern))


def put_pattern(name: str, pattern: TouchPattern | Mapping[str, Any]) -> Call[Summary]:
    return Call("PUT", f"/patterns/{_segment(name)}", _model(Summary), pattern_json(pattern))


def delete_pattern(name: str) -> Call[None]:
    return Call("DELETE", f"/patterns/{_segment(name)}", _nothing)


def play_pattern(
    name: str, *, start_in_ms: float | None = None, start_at_s: float | None = None
) -> Call[Job]:
    body = timing(start_in_ms=start_in_ms, start_at_s=start_at_s) or None
    return Call("POST", f"/patterns/{_segment(name)}/play", _model(Job), body)


def clips() -> Call[list[ClipSummary]]:
    return Call("GET", "/clips", _clip_summaries)


def get_clip(name: str) -> Call[HapticClip]:
    return Call("GET", f"/clips/{_segment(name)}", _model(HapticClip))


def put_clip(name: str, clip: HapticClip | Mapping[str, Any]) -> Call[ClipSummary]:
    body = HapticClip.model_validate(clip).model_dump(mode="json", exclude_unset=True)
    return Call("PUT", f"/clips/{_segment(name)}", _model(ClipSummary), body)


def delete_clip(name: str) -> Call[None]:
    return Call("DELETE", f"/clips/{_segment(name)}", _nothing)


_TACT_SUMMARIES = TypeAdapter(list[TactSummary])


def _tact_summaries(response: httpx.Response) -> list[TactSummary]:
    try:
        return _TACT_SUMMARIES.validate_python(_decode(response))
    except ValidationError as exc:
        raise TransportError(f"{response.request.url.path}: unexpected answer: {exc}") from exc


def tact_projects(limit: int = 100, offset: int = 0) -> Call[list[TactSummary]]:
    page = {"limit": int(limit), "offset": int(offset)}
    return Call("GET", "/tact", _tact_summaries, params=page)


def get_tact(name: str) -> Call[Any]:
    return Call("GET", f"/tact/{_segment(name)}", _decode)


def put_tact(name: str, project: Mapping[str, Any]) -> Call[TactSummary]:
    return Call("PUT", f"/tact/{_segment(name)}", _model(TactSummary), dict(project))


def delete_tact(name: str) -> Call[None]:
    return Call("DELETE", f"/tact/{_segment(name)}", _nothing)


_WORKSPACE_SUMMARIES = TypeAdapter(list[WorkspaceSummary])


def _workspace_summaries(response: httpx.Response) -> list[WorkspaceSummary]:
    try:
        return _WORKSPACE_SUMMARIES.validate_python(_decode(response))
    except ValidationError as exc:
        raise TransportError(f"{response.request.url.path}: unexpected answer: {exc}") from exc


def workspaces(limit: int = 100, offset: int = 0) -> Call[list[WorkspaceSummary]]:
    page = {"limit": int(limit), "offset": int(offset)}
    return Call("GET", "/bhaptics/workspaces", _workspace_summaries, params=page)


def get_workspace(workspace_id: str) -> Call[Any]:
    return Call("GET", f"/bhaptics/workspaces/{_segment(workspace_id)}", _decode)


def put_workspace(workspace_id: str, deployment: Mapping[str, Any]) -> Call[WorkspaceSummary]:
    path = f"/bhaptics/workspaces/{_segment(workspace_id)}"
    return Call("PUT", path, _model(WorkspaceSummary), dict(deployment))


def delete_workspace(workspace_id: str) -> Call[None]:
    return Call("DELETE", f"/bhaptics/workspaces/{_segment(workspace_id)}", _nothing)


def play_tact(
    name: str,
    *,
    intensity_scale: float | None = None,
    duration_scale: float | None = None,
    start_in_ms: float | None = None,
    start_at_s: float | None = None,
) -> Call[ScoreStarted]:
    body: dict[str, Any] = timing(start_in_ms=start_in_ms, start_at_s=start_at_s)
    if intensity_scale is not None:
        body["intensity_scale"] = intensity_scale
    if duration_scale is not None:
        body["duration_scale"] = duration_scale
    return Call("POST", f"/tact/{_segment(name)}/play", _model(ScoreStarted), body or None)


_WEARER_SUMMARIES = TypeAdapter(list[WearerSummary])


def _wearer_summaries(response: httpx.Response) -> list[WearerSummary]:
    try:
        return _WEARER_SUMMARIES.validate_python(_decode(response))
    except ValidationError as exc:
        raise TransportError(f"{response.request.url.path}: unexpected answer: {exc}") from exc


def wearers() -> Call[list[WearerSummary]]:
    return Call("GET", "/wearers", _wearer_summaries)


def get_wearer(name: str) -> Call[Wearer]:
    return Call("GET", f"/wearers/{_segment(name)}", _model(Wearer))


def put_wearer(
    name: str, offsets_db: Mapping[str, Mapping[int | str, float]], note: str = ""
) -> Call[Wearer]:
    body = {
        "offsets_db": {
            band: {str(channel): float(db) for channel, db in channels.items()}
            for band, channels in offsets_db.items()
        },
        "note": note,
    }
    return Call("PUT", f"/wearers/{_segment(name)}", _model(Wearer), body)


def delete_wearer(name: str) -> Call[None]:
    return Call("DELETE", f"/wearers/{_segment(name)}", _nothing)


def wearer_run(name: str) -> Call[WearerRun]:
    return Call("GET", f"/wearers/{_segment(name)}/run", _model(WearerRun))


def put_wearer_run(
    name: str, band: str, reference_channel: int, trials: Sequence[Mapping[str, Any]]
) -> Call[WearerRun]:
    body = {"band": band, "reference_channel": reference_channel, "trials": list(trials)}
    return Call("PUT", f"/wearers/{_segment(name)}/run", _model(WearerRun), body)


def delete_wearer_run(name: str) -> Call[None]:
    return Call("DELETE", f"/wearers/{_segment(name)}/run", _nothing)


def active_wearer() -> Call[ActiveWearer]:
    return Call("GET", "/wearer", _model(ActiveWearer))


def use_wearer(name: str, band: str = "sine_100hz") -> Call[ActiveWearer]:
    return Call("PUT", "/wearer", _model(ActiveWearer), {"name": name, "band": band})


def no_wearer() -> Call[None]:
    return Call("DELETE", "/wearer", _nothing)


def device() -> Call[DeviceInfo]:
    return Call("GET", "/device", _model(DeviceInfo))


def presets() -> Call[list[Summary]]:
    return Call("GET", "/presets", _summaries)


def clock() -> Call[Clock]:
    return Call("GET", "/clock", _model(Clock))


def health() -> Call[Health]:
    return Call("GET", "/health", _model(Health))


def metrics() -> Call[str]:
    return Call("GET", "/metrics", _text, accept="text/plain")
