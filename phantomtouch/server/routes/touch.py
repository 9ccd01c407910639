"""Triggered touches: ``POST /touch``, ``POST /stop``, ``GET|DELETE /jobs/{job_id}``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any

from fastapi import APIRouter, Depends, Request
from fastapi import Path as PathParam

from phantomtouch.server.deps import ArrivalDep, EngineDep, ServiceDep, SourceDep
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import NotFoundError, responses

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront
from phantomtouch.service.models import (
    AnyTouch,
    JobAccepted,
    JobInfo,
    StopAnswer,
    current_words,
    touch_request_adapter,
)

router = APIRouter(tags=["touch"])

_wire_touch_body, TOUCH_BODY_OPENAPI = strict_body(touch_request_adapter)


async def touch_body(request: Request) -> AnyTouch:
    """The touch request of the body, a deprecated ``pattern`` renamed ``stored``."""
    return current_words(await _wire_touch_body(request))


TouchBody = Annotated[AnyTouch, Depends(touch_body)]

JobIdParam = Annotated[
    str, PathParam(min_length=1, max_length=64, description="As `POST /touch` answered it.")
]


SCHEDULES: dict[str, Any] = {
    "status_code": 202,
    "response_model": JobAccepted,
    "responses": responses(401, 404, 413, 415, 422, 429, 500, 503),
}
"""How a route that schedules a touch answers (``POST /touch``, ``POST
/patterns/{name}/play``): 202 with the job, or one of these errors."""


@router.post("/touch", **SCHEDULES, summary="Play a touch", openapi_extra=TOUCH_BODY_OPENAPI)
async def post_touch(request: TouchBody, source: SourceDep, arrival: ArrivalDep) -> JobAccepted:
    """Schedule a touch: a whole pattern, a preset with overrides, or a stored pattern.

    Without `start_in_ms` or `start_at_s` it starts as soon as possible. 404 names an
    unknown preset or stored pattern; 503 `busy` means the engine's queue is full; 429
    `quota` that this client holds its share of the voices (the message names the quota).
    """
    return await source.play(request, arrival=arrival)


@router.post(
    "/stop",
    response_model=StopAnswer,
    responses=responses(401),
    summary="Everything off",
)
async def post_stop(service: ServiceDep) -> StopAnswer:
    """Stop every job and release every contact of every client, at once.

    Runs on the event loop directly (never behind a worker queue) and never answers
    `busy`.
    """
    service.stop_everything()
    return StopAnswer(
        server_time_s=service.engine.server_time_s(), frames=service.engine.now_frames
    )


JOB_ANSWER: dict[str, Any] = {
    "response_model": JobInfo,
    "response_model_exclude_none": True,
    "responses": responses(401, 404, 422),
}
"""How ``GET|DELETE /jobs/{job_id}`` answer: the job's state, or one of these errors."""


def job_info(engine: EngineFront, job_id: str) -> JobInfo:
    """A job's state; an unknown id is :class:`NotFoundError`."""
    state = engine.job_state(job_id)
    if state is None:
        raise NotFoundError(f"job_id={job_id!r} is not a known job", field="job_id", value=job_id)
    return JobInfo(
        job_id=job_id,
        state=state.state,
        start_at_s=(
            state.requested_start_at_s
            if state.requested_start_at_s is not None
            and state.start_frame == state.requested_start_frame
            else engine.time_at(state.start_frame)
        ),
        start_frame=state.start_frame,
        end_at_s=engine.time_at(state.end_frame),
        end_frame=state.end_frame,
        duration_s=state.duration_s,
        late=state.late,
        reason=state.reason,
    )


@router.get("/jobs/{job_id}", **JOB_ANSWER, summary="A job")
async def get_job(job_id: JobIdParam, engine: EngineDep) -> JobInfo:
    """Where a job is: `scheduled`, `playing`, `finished` or `stopped` (with a `reason`
    when it stopped unasked: stolen, or the engine's fault)."""
    return job_info(engine, job_id)


@router.delete("/jobs/{job_id}", **JOB_ANSWER, summary="Stop a job")
async def delete_job(job_id: JobIdParam, engine: EngineDep) -> JobInfo:
    """Stop one job (with its release ramp) and answer its new state.

    A job that is over already keeps its state (`finished` or `stopped`).
    """
    engine.stop(job_id)
    return job_info(engine, job_id)
