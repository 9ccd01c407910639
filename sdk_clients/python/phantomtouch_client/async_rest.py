"""The asyncio REST client, :class:`AsyncClient`, over httpx.

The twin of the blocking :class:`~phantomtouch_client.Client`: the same methods and
answers, awaited. The routes are described once, in :mod:`phantomtouch_client._calls`, and
what the two clients share is in :mod:`phantomtouch_client.rest_base`.
"""

from __future__ import annotations

import asyncio
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
    from phantomtouch_client.session import AsyncSession

T = TypeVar("T")


class AsyncClient(ClientBase):
    """The asyncio twin of :class:`Client`: the same methods, awaited.

    >>> async with AsyncClient() as pt:                        # doctest: +SKIP
    ...     job = await pt.touch(preset="exp2/curved")
    """

    def __init__(
        self,
        base_url: str = DEFAULT_URL,
        *,
        token: str | None = None,
        timeout_s: float = 10.0,
        retries: int = 2,
        max_retry_wait_s: float = 5.0,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        super().__init__(base_url, token, timeout_s, retries, max_retry_wait_s)
        self._http = httpx.AsyncClient(
            base_url=self.base_url,
            headers=auth_headers(token),
            timeout=timeout_s,
            transport=transport,
        )

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        await self._http.aclose()

    async def _run(self, call: _calls.Call[T]) -> T:
        attempt = 0
        while True:
            try:
                response = await self._http.request(
                    call.method, call.path, **self._request_args(call)
                )
            except httpx.HTTPError as exc:
                raise self._failed(call, exc) from exc
            wait_s = self._retry_wait_s(response, attempt)
            if wait_s is None:
                return call.parse(response)
            attempt += 1
            await asyncio.sleep(wait_s)

    def session(self, **options: Any) -> AsyncSession:
        """A WebSocket session with this client's address and token (not yet connected).

        ``options`` are those of :class:`~phantomtouch_client.AsyncSession`.
        """
        from phantomtouch_client.session import AsyncSession

        return AsyncSession(ws_url(self.base_url), token=self.token, **options)

    async def touch(
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
        return await self._run(call)

    async def render(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> bytes:
        """``POST /render``: the touch as a WAV file (float32, one channel per actuator)."""
        body = touch_request(pattern, preset=preset, stored=stored, overrides=overrides)
        return await self._run(_calls.render_wav(body))

    async def render_plan(
        self,
        pattern: PatternArg = None,
        *,
        preset: str | None = None,
        stored: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> RenderPlan:
        """``POST /render`` as JSON: the plan and its curves (times, positions, gains)."""
        body = touch_request(pattern, preset=preset, stored=stored, overrides=overrides)
        return await self._run(_calls.render_plan(body))

    async def job(self, job_id: JobId) -> JobStatus:
        """``GET /jobs/{id}``."""
        return await self._run(_calls.job(job_id))

    async def cancel_job(self, job_id: JobId) -> JobStatus:
        """``DELETE /jobs/{id}``: stop that job with its release ramp."""
        return await self._run(_calls.cancel_job(job_id))

    async def armbands(self) -> list[dict[str, Any]]:
        """``GET /armbands`` of a fleet gateway: the armbands online, with their devices."""
        return await self._run(_calls.armbands())

    async def stop(self) -> StopAnswer:
        """``POST /stop``: every job and contact of every client off at once."""
        return await self._run(_calls.stop())

    async def patterns(self) -> list[Summary]:
        """``GET /patterns``: the stored patterns."""
        return await self._run(_calls.patterns())

    async def get_pattern(self, name: str) -> TouchPattern:
        """``GET /patterns/{name}``."""
        return await self._run(_calls.get_pattern(name))

    async def put_pattern(self, name: str, pattern: TouchPattern | Mapping[str, Any]) -> Summary:
        """``PUT /patterns/{name}``: store (or replace) a pattern under ``name``."""
        return await self._run(_calls.put_pattern(name, pattern))

    async def delete_pattern(self, name: str) -> None:
        """``DELETE /patterns/{name}``."""
        await self._run(_calls.delete_pattern(name))

    async def play_pattern(
        self, name: str, *, start_in_ms: float | None = None, start_at_s: float | None = None
    ) -> Job:
        """``POST /patterns/{name}/play``."""
        return await self._run(
            _calls.play_pattern(name, start_in_ms=start_in_ms, start_at_s=start_at_s)
        )

    async def clips(self) -> list[ClipSummary]:
        """``GET /clips``: the stored haptic clips."""
        return await self._run(_calls.clips())

    async def get_clip(self, name: str) -> HapticClip:
        """``GET /clips/{name}``."""
        return await self._run(_calls.get_clip(name))

    async def put_clip(self, name: str, clip: HapticClip | Mapping[str, Any]) -> ClipSummary:
        """``PUT /clips/{name}``: store (or replace) a clip."""
        return await self._run(_calls.put_clip(name, clip))

    async def delete_clip(self, name: str) -> None:
        """``DELETE /clips/{name}``."""
        await self._run(_calls.delete_clip(name))

    async def tact_projects(self, *, limit: int = 100, offset: int = 0) -> list[TactSummary]:
        """``GET /tact``: one page of the stored ``.tact`` projects, sorted by name."""
        return await self._run(_calls.tact_projects(limit, offset))

    async def get_tact(self, name: str) -> Any:
        """``GET /tact/{name}``: the project's JSON as stored."""
        return await self._run(_calls.get_tact(name))

    async def put_tact(self, name: str, project: Mapping[str, Any]) -> TactSummary:
        """``PUT /tact/{name}``: store (or replace) a ``.tact`` file's JSON."""
        return await self._run(_calls.put_tact(name, project))

    async def workspaces(self, *, limit: int = 100, offset: int = 0) -> list[WorkspaceSummary]:
        """``GET /bhaptics/workspaces``: one page of the stored SDK2 workspaces (games'
        deployments), sorted by id."""
        return await self._run(_calls.workspaces(limit, offset))

    async def get_workspace(self, workspace_id: str) -> Any:
        """``GET /bhaptics/workspaces/{workspace_id}``: the deployment's JSON as stored."""
        return await self._run(_calls.get_workspace(workspace_id))

    async def put_workspace(
        self, workspace_id: str, deployment: Mapping[str, Any]
    ) -> WorkspaceSummary:
        """``PUT /bhaptics/workspaces/{workspace_id}``: store (or replace) a game's
        deployment; a game connecting with this id plays its events by name."""
        return await self._run(_calls.put_workspace(workspace_id, deployment))

    async def delete_workspace(self, workspace_id: str) -> None:
        """``DELETE /bhaptics/workspaces/{workspace_id}``."""
        await self._run(_calls.delete_workspace(workspace_id))

    async def delete_tact(self, name: str) -> None:
        """``DELETE /tact/{name}``."""
        await self._run(_calls.delete_tact(name))

    async def play_tact(
        self,
        name: str,
        *,
        intensity_scale: float | None = None,
        duration_scale: float | None = None,
        start_in_ms: float | None = None,
        start_at_s: float | None = None,
    ) -> ScoreStarted:
        """``POST /tact/{name}/play``: every voice of the project, one job each."""
        return await self._run(
            _calls.play_tact(
                name,
                intensity_scale=intensity_scale,
                duration_scale=duration_scale,
                start_in_ms=start_in_ms,
                start_at_s=start_at_s,
            )
        )

    async def wearers(self) -> list[WearerSummary]:
        """``GET /wearers``: the stored wearer profiles."""
        return await self._run(_calls.wearers())

    async def get_wearer(self, name: str) -> Wearer:
        """``GET /wearers/{name}``."""
        return await self._run(_calls.get_wearer(name))

    async def put_wearer(
        self, name: str, offsets_db: Mapping[str, Mapping[int | str, float]], note: str = ""
    ) -> Wearer:
        """``PUT /wearers/{name}``: offsets in dB per band and actuator, within ±20 dB."""
        return await self._run(_calls.put_wearer(name, offsets_db, note))

    async def delete_wearer(self, name: str) -> None:
        """``DELETE /wearers/{name}``."""
        await self._run(_calls.delete_wearer(name))

    async def wearer_run(self, name: str) -> WearerRun:
        """``GET /wearers/{name}/run``: the answers of the wearer's matching run so far."""
        return await self._run(_calls.wearer_run(name))

    async def put_wearer_run(
        self,
        name: str,
        band: str,
        reference_channel: int,
        trials: Sequence[Mapping[str, Any]],
    ) -> WearerRun:
        """``PUT /wearers/{name}/run``: store the answers of a matching run so far (each
        trial ``{"channel", "level_db", "test_stronger"}``); a record, never applied."""
        return await self._run(_calls.put_wearer_run(name, band, reference_channel, trials))

    async def delete_wearer_run(self, name: str) -> None:
        """``DELETE /wearers/{name}/run``."""
        await self._run(_calls.delete_wearer_run(name))

    async def wearer(self) -> ActiveWearer:
        """``GET /wearer``: the wearer the output stage is fitted to now."""
        return await self._run(_calls.active_wearer())

    async def use_wearer(self, name: str, band: str = "sine_100hz") -> ActiveWearer:
        """``PUT /wearer``: fit the output stage to the stored profile ``name`` (its
        ``band``) from the next block on, until another is chosen."""
        return await self._run(_calls.use_wearer(name, band))

    async def no_wearer(self) -> None:
        """``DELETE /wearer``: the device's calibration alone from the next block on."""
        await self._run(_calls.no_wearer())

    async def device(self) -> DeviceInfo:
        """``GET /device``."""
        return await self._run(_calls.device())

    async def presets(self) -> list[Summary]:
        """``GET /presets``."""
        return await self._run(_calls.presets())

    async def clock(self) -> Clock:
        """``GET /clock``: the server clock, for ``start_at_s``."""
        return await self._run(_calls.clock())

    async def health(self) -> Health:
        """``GET /health``."""
        return await self._run(_calls.health())

    async def metrics(self) -> str:
        """``GET /metrics``: Prometheus text."""
        return await self._run(_calls.metrics())
