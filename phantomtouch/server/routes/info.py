"""What the service is and does: device, presets, clock, health, metrics."""

from __future__ import annotations

import functools
import time

from fastapi import APIRouter, Response

from phantomtouch.renderer import preset_names
from phantomtouch.schema import DeviceProfile
from phantomtouch.server.deps import EngineDep, ServiceDep
from phantomtouch.service import scheduling
from phantomtouch.service.errors import responses
from phantomtouch.service.metrics import CONTENT_TYPE
from phantomtouch.service.models import (
    ClockInfo,
    DeviceInfo,
    Health,
    InputState,
    PlanSummary,
    PresetInfo,
)

router = APIRouter(tags=["info"])


@router.get("/device", response_model=DeviceInfo, responses=responses(401), summary="The armband")
async def get_device(engine: EngineDep) -> DeviceInfo:
    """Layout (actuators, triangles), channels, timing, where the engine plays, and the
    strongest level a touch may ask for (`max_level_db`)."""
    status = engine.status().to_dict()
    device: DeviceProfile = engine.device
    return DeviceInfo(
        name=device.name,
        backend=status["backend"],
        output_device=status["output_device"],
        channels=status["channels"],
        sample_rate_hz=status["sample_rate_hz"],
        block_frames=status["block_frames"],
        period_frames=status["period_frames"],
        period_source=status["period_source"],
        output_latency_s=status["output_latency_s"],
        actuators=list(device.actuators),
        triangles=list(engine_triangles(device)),
        max_level_db=device.safety.max_level_db,
    )


def engine_triangles(device: DeviceProfile) -> tuple[tuple[int, int, int], ...]:
    """The triangles the renderer uses (the profile's, or its Delaunay triangulation)."""
    from phantomtouch.renderer import Geometry

    triangles = Geometry.for_device(device).triangles
    return tuple((int(a), int(b), int(c)) for a, b, c in triangles)


@functools.cache
def _preset_summaries(device: DeviceProfile) -> tuple[PresetInfo, ...]:
    return tuple(
        PresetInfo(
            name=name,
            summary=PlanSummary(
                **scheduling.plan_summary(
                    scheduling.plan_for(scheduling.preset_pattern(name), device)
                )
            ),
        )
        for name in preset_names()
    )


@router.get(
    "/presets", response_model=list[PresetInfo], responses=responses(401), summary="The presets"
)
def get_presets(service: ServiceDep) -> list[PresetInfo]:
    """Every preset with its plan summary on this device."""
    return list(_preset_summaries(service.device))


@router.get("/clock", response_model=ClockInfo, responses=responses(401), summary="Server clock")
async def get_clock(engine: EngineDep) -> ClockInfo:
    """The server clock that `start_at_s` and WebSocket times refer to."""
    return ClockInfo(
        server_time_s=engine.server_time_s(),
        frames=engine.now_frames,
        sample_rate_hz=engine.sample_rate_hz,
        unix_time_s=time.time(),
    )


@router.get("/health", response_model=Health, response_model_exclude_none=True, summary="Liveness")
async def get_health(service: ServiceDep) -> Health:
    """`ok` while audio flows and the pattern store works; `degraded` while the engine is
    being restarted (`engine` says its state) or naming the store's problem (`storage`:
    its disk is full or its file damaged). `wearer` names the wearer profile the output
    stage applies now (and `wearer_band` its band), when there is one (`GET /wearer`
    adds its offsets). Needs no token, and
    never waits for the engine (its figures come from shared memory)."""
    status = service.engine.status()
    problem = service.store.problem
    wearer = service.wearer.choice
    inputs = {name: health() for name, health in service.inputs.items()}
    degraded = sorted(name for name, state in inputs.items() if state.degraded)
    return Health(
        status="ok"
        if status.state == "running" and problem is None and not degraded
        else "degraded",
        backend=status.backend,
        engine=status.state,
        underruns=status.underruns,
        render_load_p99=status.render_load_p99,
        storage=problem,
        inputs={
            name: InputState(state=s.state, restarts=s.restarts, last_failure=s.last_failure)
            for name, s in inputs.items()
        }
        or None,
        degraded_inputs=degraded or None,
        wearer=None if wearer is None else wearer.name,
        wearer_band=None if wearer is None else wearer.band,
    )


@router.get(
    "/metrics",
    response_class=Response,
    responses={200: {"content": {CONTENT_TYPE: {"schema": {"type": "string"}}}}, **responses(401)},
    summary="Prometheus metrics",
)
async def get_metrics(service: ServiceDep) -> Response:
    """Requests, latency, WebSocket messages, active voices, underruns, late commands, peak."""
    return Response(service.metrics.exposition(), media_type=CONTENT_TYPE)
