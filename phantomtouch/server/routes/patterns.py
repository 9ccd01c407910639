"""The pattern library: ``GET /patterns``, ``GET|PUT|DELETE /patterns/{name}``, play."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Response
from pydantic import TypeAdapter

from phantomtouch.schema import TouchPattern
from phantomtouch.server.deps import ClientDep, PatternNameParam, ServiceDep, StoreDep
from phantomtouch.service import scheduling
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import NotFoundError, responses
from phantomtouch.service.models import (
    JobAccepted,
    NamedTouch,
    PatternInfo,
    PlanSummary,
    PlayRequest,
)

router = APIRouter(prefix="/patterns", tags=["patterns"])

pattern_body, PATTERN_BODY_OPENAPI = strict_body(TypeAdapter(TouchPattern))
play_body, PLAY_BODY_OPENAPI = strict_body(
    TypeAdapter(PlayRequest), required=False, default=PlayRequest()
)


@router.get(
    "", response_model=list[PatternInfo], responses=responses(401, 503), summary="The library"
)
def list_patterns(store: StoreDep) -> list[PatternInfo]:
    """Every stored pattern with its plan summary, sorted by name."""
    return [
        PatternInfo(name=name, summary=PlanSummary(**summary)) for name, summary in store.list()
    ]


@router.get(
    "/{name}",
    response_model=TouchPattern,
    response_model_exclude_unset=True,
    responses=responses(401, 404, 422, 500, 503),
    summary="One stored pattern",
)
def get_pattern(name: PatternNameParam, store: StoreDep) -> TouchPattern:
    """The pattern as it was stored with `PUT`."""
    return scheduling.stored_pattern(store, name, field="name")


@router.put(
    "/{name}",
    response_model=PatternInfo,
    responses=responses(401, 413, 415, 422, 503),
    summary="Store a pattern",
    openapi_extra=PATTERN_BODY_OPENAPI,
)
def put_pattern(
    name: PatternNameParam,
    pattern: Annotated[TouchPattern, Depends(pattern_body)],
    service: ServiceDep,
) -> PatternInfo:
    """Store (or replace) a pattern; it is planned first, so only playable patterns are kept."""
    summary = scheduling.plan_summary(
        service.plans.plan(scheduling.with_clip(pattern, service.store))
    )
    service.store.put(name, pattern, summary)
    return PatternInfo(name=name, summary=PlanSummary(**summary))


@router.delete(
    "/{name}", status_code=204, responses=responses(401, 404, 422, 503), summary="Remove a pattern"
)
def delete_pattern(name: PatternNameParam, store: StoreDep) -> Response:
    """Remove a stored pattern."""
    if not store.delete(name):
        raise NotFoundError(
            f"name={name!r} is not in the pattern library (GET /patterns)",
            field="name",
            value=name,
        )
    return Response(status_code=204)


@router.post(
    "/{name}/play",
    status_code=202,
    response_model=JobAccepted,
    responses=responses(401, 404, 413, 415, 422, 429, 500, 503),
    summary="Play a stored pattern",
    openapi_extra=PLAY_BODY_OPENAPI,
)
async def play_pattern(
    name: PatternNameParam,
    service: ServiceDep,
    timing: Annotated[PlayRequest, Depends(play_body)],
    client: ClientDep,
) -> JobAccepted:
    """As `POST /touch` with `{"stored": name}`; optional `start_in_ms` or `start_at_s`."""
    request = NamedTouch(stored=name, start_in_ms=timing.start_in_ms, start_at_s=timing.start_at_s)
    return await scheduling.schedule(service, request, client=client)
