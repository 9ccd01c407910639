"""The blocking REST client, :class:`Client`, over httpx.

It covers every route of the service; the routes themselves are described once, in
:mod:`phantomtouch_client._calls`, and what it shares with its asyncio twin
(:class:`~phantomtouch_client.AsyncClient`) is in :mod:`phantomtouch_client.rest_base`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self, TypeVar

import httpx

from phantomtouch_client import _calls
from phantomtouch_client.models import (
    ActiveWearer,
    ClipSummary,
    Clock,
    DeviceInfo,
    Health,
    Job,
    JobId,
    JobStatus,
    PatternArg,
    RenderPlan,
    ScoreStarted,
    StopAnswer,
    Summary,
    TactSummary,
    Wearer,
    WearerRun,
    WearerSummary,
    WorkspaceSummary,
    touch_request,
)
from phantomtouch_client.pattern import HapticClip, TouchPattern
from phantomtouch_client.rest_base import DEFAULT_URL, ClientBase, auth_headers, ws_url

if TYPE_CHECKING:
    from phantomtouch_client.sync_session import Session

T = TypeVar("T")


class Client(ClientBase):
    """A blocking client of the REST API.

    >>> with Client("http://127.0.0.1:8000") as pt:          # doctest: +SKIP
    ...     job = pt.touch(preset="exp2/curved", start_in_ms=20)
    ...     pt.job(job.job_id).state
    'scheduled'

    ``token`` is the service token (required when the service listens off loopback);
    ``timeout_s`` bounds every request. A 429 or 503 answer with a ``Retry-After`` of at
    most ``max_retry_wait_s`` is retried after that wait, ``retries`` times at most; then
    (or with a longer wait) it is raised. ``transport`` is handed to httpx (for tests).
    """

    def __init__(
        self,
        base_url: str = DEFAULT_URL,
        *,
        token: str | None = None,
        timeout_s: float = 10.0,
        retries: int = 2,
        max_retry_wait_s: float = 5.0,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        super().__init__(base_url, token, timeout_s, retries, max_retry_wait_s)
        self._http = httpx.Client(
            base_url=self.base_url,
            headers=auth_headers(token),
            timeout=timeout_s,
            transport=transport,
        )

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    def _run(self, call: _calls.Call[T]) -> T:
        attempt = 0
        while True:
            try:
                response = self._http.request(call.method, call.path, **self._request_args(call))
            except httpx.HTTPError as exc:
                raise self._failed(call, exc) from exc
            wait_s = self._retry_wait_s(response, attempt)
            if wait_s is None:
                return call.parse(response)
            attempt += 1
            time.sleep(wait_s)

    def session(self, **options: Any) -> Session:
        """A WebSocket session with this client's address and token (not yet connected).

        ``options`` are those of :class:`~phantomtouch_client.Session`.
        """
        from phantomtouch_client.sync_session import Session

        return Session(ws_url(self.base_url), token=self.token, **options)

    def touch(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
        start_in_ms: float | None = None,
        start_at_s: float | None = None,
        armband: str | None = None,
        start_at_unix_s: float | None = None,
    ) -> Job:
        """``POST /touch``: schedule a touch; see :func:`~phantomtouch_client.touch_request`.

        Through a fleet gateway, ``armband`` addresses one armband
        (``POST /armbands/{armband}/touch``) and ``start_at_unix_s`` starts it at that
        wall-clock time (the same instant on every armband sent it); the answer then also
        carries ``armband``, ``site`` and ``start_at_unix_s``.
        """
        call = self._touch_call(
            pattern,
            preset=preset,
            stored=stored,
            overrides=overrides,
            start_in_ms=start_in_ms,
            start_at_s=start_at_s,
            armband=armband,
            start_at_unix_s=start_at_unix_s,
        )
        return self._run(call)

    def render(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> bytes:
        """``POST /render``: the touch as a WAV file (float32, one channel per actuator)."""
        body = touch_request(pattern, preset=preset, stored=stored, overrides=overrides)
        return self._run(_calls.render_wav(body))

    def render_plan(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> RenderPlan:
        """``POST /render`` as JSON: the plan and its curves (times, positions, gains)."""
        body = touch_request(pattern, preset=preset, stored=stored, overrides=overrides)
        return self._run(_calls.render_plan(body))

    def job(self, job_id: JobId) -> JobStatus:
        """``GET /jobs/{id}``."""
        return self._run(_calls.job(job_id))

    def cancel_job(self, job_id: JobId) -> JobStatus:
        """``DELETE /jobs/{id}``: stop that job with its release ramp."""
        return self._run(_calls.cancel_job(job_id))

    def stop(self) -> StopAnswer:
        """``POST /stop``: every job and contact of every client off at once."""
        return self._run(_calls.stop())

    def armbands(self) -> list[dict[str, Any]]:
        """``GET /armbands`` of a fleet gateway: the armbands online, with their devices."""
        return self._run(_calls.armbands())

    def patterns(self) -> list[Summary]:
        """``GET /patterns``: the stored patterns."""
        return self._run(_calls.patterns())

    def get_pattern(self, name: str) -> TouchPattern:
        """``GET /patterns/{name}``."""
        return self._run(_calls.get_pattern(name))

    def put_pattern(self, name: str, pattern: TouchPattern | Mapping[str, Any]) -> Summary:
        """``PUT /patterns/{name}``: store (or replace) a pattern under ``name``."""
        return self._run(_calls.put_pattern(name, pattern))

    def delete_pattern(self, name: str) -> None:
        """``DELETE /patterns/{name}``."""
        self._run(_calls.delete_pattern(name))

    def play_pattern(
        self, name: str, *, start_in_ms: float | None = None, start_at_s: float | None = None
    ) -> Job:
        """``POST /patterns/{name}/play``."""
        return self._run(_calls.play_pattern(name, start_in_ms=start_in_ms, start_at_s=start_at_s))

    def clips(self) -> list[ClipSummary]:
        """``GET /clips``: the stored haptic clips."""
        return self._run(_calls.clips())

    def get_clip(self, name: str) -> HapticClip:
        """``GET /clips/{name}``."""
        return self._run(_calls.get_clip(name))

    def put_clip(self, name: str, clip: HapticClip | Mapping[str, Any]) -> ClipSummary:
        """``PUT /clips/{name}``: store (or replace) a clip; a pattern plays it with
        ``carrier={"kind": "clip", "clip": name}``."""
        return self._run(_calls.put_clip(name, clip))

    def delete_clip(self, name: str) -> None:
        """``DELETE /clips/{name}``."""
        self._run(_calls.delete_clip(name))

    def tact_projects(self, *, limit: int = 100, offset: int = 0) -> list[TactSummary]:
        """``GET /tact``: one page of the stored ``.tact`` projects, sorted by name."""
        return self._run(_calls.tact_projects(limit, offset))

    def get_tact(self, name: str) -> Any:
        """``GET /tact/{name}``: the project's JSON as stored."""
        return self._run(_calls.get_tact(name))

    def put_tact(self, name: str, project: Mapping[str, Any]) -> TactSummary:
        """``PUT /tact/{name}``: store (or replace) a ``.tact`` file's JSON."""
        return self._run(_calls.put_tact(name, project))

    def workspaces(self, *, limit: int = 100, offset: int = 0) -> list[WorkspaceSummary]:
        """``GET /bhaptics/workspaces``: one page of the stored SDK2 workspaces (games'
        deployments), sorted by id."""
        return self._run(_calls.workspaces(limit, offset))

    def get_workspace(self, workspace_id: str) -> Any:
        """``GET /bhaptics/workspaces/{workspace_id}``: the deployment's JSON as stored."""
        return self._run(_calls.get_workspace(workspace_id))

    def put_workspace(self, workspace_id: str, deployment: Mapping[str, Any]) -> WorkspaceSummary:
        """``PUT /bhaptics/workspaces/{workspace_id}``: store (or replace) a game's
        deployment; a game connecting with this id plays its events by name."""
        return self._run(_calls.put_workspace(workspace_id, deployment))

    def delete_workspace(self, workspace_id: str) -> None:
        """``DELETE /bhaptics/workspaces/{workspace_id}``."""
        self._run(_calls.delete_workspace(workspace_id))

    def delete_tact(self, name: str) -> None:
        """``DELETE /tact/{name}``."""
        self._run(_calls.delete_tact(name))

    def play_tact(
        self,
        name: str,
        *,
        intensity_scale: float | None = None,
        duration_scale: float | None = None,
        start_in_ms: float | None = None,
        start_at_s: float | None = None,
    ) -> ScoreStarted:
        """``POST /tact/{name}/play``: every voice of the project, one job each."""
        return self._run(
            _calls.play_tact(
                name,
                intensity_scale=intensity_scale,
                duration_scale=duration_scale,
                start_in_ms=start_in_ms,
                start_at_s=start_at_s,
            )
        )

    def wearers(self) -> list[WearerSummary]:
        """``GET /wearers``: the stored wearer profiles; ``active`` marks the one the
        service's output stage applies."""
        return self._run(_calls.wearers())

    def get_wearer(self, name: str) -> Wearer:
        """``GET /wearers/{name}``."""
        return self._run(_calls.get_wearer(name))

    def put_wearer(
        self, name: str, offsets_db: Mapping[str, Mapping[int | str, float]], note: str = ""
    ) -> Wearer:
        """``PUT /wearers/{name}``: per band (``sine_100hz``, ``noise_40_500hz``) and
        actuator (output channel, 1-based) an offset in dB within ±20 dB. The service
        applies it once chosen (:meth:`use_wearer`, ``serve --wearer NAME``)."""
        return self._run(_calls.put_wearer(name, offsets_db, note))

    def delete_wearer(self, name: str) -> None:
        """``DELETE /wearers/{name}``."""
        self._run(_calls.delete_wearer(name))

    def wearer_run(self, name: str) -> WearerRun:
        """``GET /wearers/{name}/run``: the answers of the wearer's matching run so far."""
        return self._run(_calls.wearer_run(name))

    def put_wearer_run(
        self,
        name: str,
        band: str,
        reference_channel: int,
        trials: Sequence[Mapping[str, Any]],
    ) -> WearerRun:
        """``PUT /wearers/{name}/run``: store the answers of a matching run so far (each
        trial ``{"channel", "level_db", "test_stronger"}``); a record, never applied."""
        return self._run(_calls.put_wearer_run(name, band, reference_channel, trials))

    def delete_wearer_run(self, name: str) -> None:
        """``DELETE /wearers/{name}/run``."""
        self._run(_calls.delete_wearer_run(name))

    def wearer(self) -> ActiveWearer:
        """``GET /wearer``: the wearer the output stage is fitted to now."""
        return self._run(_calls.active_wearer())

    def use_wearer(self, name: str, band: str = "sine_100hz") -> ActiveWearer:
        """``PUT /wearer``: fit the output stage to the stored profile ``name`` (its
        ``band``: ``sine_100hz`` or ``noise_40_500hz``) from the next block on, for
        everything the service plays, until another is chosen."""
        return self._run(_calls.use_wearer(name, band))

    def no_wearer(self) -> None:
        """``DELETE /wearer``: the device's calibration alone from the next block on."""
        self._run(_calls.no_wearer())

    def device(self) -> DeviceInfo:
        """``GET /device``."""
        return self._run(_calls.device())

    def presets(self) -> list[Summary]:
        """``GET /presets``."""
        return self._run(_calls.presets())

    def clock(self) -> Clock:
        """``GET /clock``: the server clock, for ``start_at_s``."""
        return self._run(_calls.clock())

    def health(self) -> Health:
        """``GET /health``."""
        return self._run(_calls.health())

    def metrics(self) -> str:
        """``GET /metrics``: Prometheus text."""
        return self._run(_calls.metrics())
