"""Triggered touches: ``POST /touch``, ``POST /stop``, ``GET|DELETE /jobs/{job_id}``."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends
from fastapi import Path as PathParam

from phantomtouch.server import touch
from phantomtouch.server.bodies import strict_body
from phantomtouch.server.deps import EngineDep, StoreDep
from phantomtouch.server.errors import NotFoundError, responses
from phantomtouch.server.models import (
    JobAccepted,
    JobInfo,
    NamedTouch,
    PatternTouch,
    PresetTouch,
    StopAnswer,
    touch_request_adapter,
)

router = APIRouter(tags=["touch"])

touch_body, TOUCH_BODY_OPENAPI = strict_body(touch_request_adapter)
TouchBody = Annotated[PatternTouch | PresetTouch | NamedTouch, Depends(touch_body)]

JobIdParam = Annotated[
    str, PathParam(min_length=1, max_length=64, description="As `POST /touch` answered it.")
]


@router.post(
    "/touch",
    status_code=202,
    response_model=JobAccepted,
    responses=responses(401, 404, 413, 422, 503),
    summary="Play a touch",
    openapi_extra=TOUCH_BODY_OPENAPI,
)
async def post_touch(request: TouchBody, engine: EngineDep, store: StoreDep) -> JobAccepted:
    """Schedule a touch: a whole pattern, a preset with overrides, or a stored pattern.

    Without `start_in_ms` or `start_at_s` it starts as soon as possible. 404 names an
    unknown preset or stored pattern; 503 `busy` means the engine's queue is full.
    """
    return touch.schedule(engine, request, store)


@router.post(
    "/stop",
    response_model=StopAnswer,
    responses=responses(401),
    summary="Everything off",
)
async def post_stop(engine: EngineDep) -> StopAnswer:
    """Stop every job and release every contact of every client, at once.

    Runs on the event loop directly (never behind a worker queue) and never answers
    `busy`.
    """
    engine.stop_all()
    return StopAnswer(server_time_s=engine.server_time_s())


def job_info(engine: Any, job_id: str) -> JobInfo:
    """A job's state; an unknown id is :class:`NotFoundError`."""
    key = touch.job_key(job_id)
    state = None if key is None else engine.job_state(key)
    if state is None:
        raise NotFoundError(f"job_id={job_id!r} is not a known job", field="job_id", value=job_id)
    end_frame = state.end_frame
    return JobInfo(
        job_id=job_id,
        state=state.state,
        start_at_s=engine.time_at(state.start_frame),
        start_frame=state.start_frame,
        end_at_s=None if end_frame is None else engine.time_at(end_frame),
        end_frame=end_frame,
        duration_s=None
        if end_frame is None
        else (end_frame - state.start_frame) / engine.sample_rate_hz,
    )


@router.get(
    "/jobs/{job_id}", response_model=JobInfo, responses=responses(401, 404, 422), summary="A job"
)
async def get_job(job_id: JobIdParam, engine: EngineDep) -> JobInfo:
    """Where a job is: `scheduled`, `playing`, `finished` or `stopped`."""
    return job_info(engine, job_id)


@router.delete(
    "/jobs/{job_id}",
    response_model=JobInfo,
    responses=responses(401, 404, 422),
    summary="Stop a job",
)
async def delete_job(job_id: JobIdParam, engine: EngineDep) -> JobInfo:
    """Stop one job (with its release ramp) and answer its new state."""
    key = touch.job_key(job_id)
    if key is None or engine.job_state(key) is None:
        raise NotFoundError(f"job_id={job_id!r} is not a known job", field="job_id", value=job_id)
    engine.stop(key)
    return job_info(engine, job_id)
