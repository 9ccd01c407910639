"""The pattern library: ``GET /patterns``, ``GET|PUT|DELETE /patterns/{name}``, play."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Response
from pydantic import TypeAdapter

from phantomtouch.schema import TouchPattern
from phantomtouch.server.deps import ArrivalDep, PatternNameParam, ServiceDep, SourceDep, StoreDep
from phantomtouch.server.routes import library
from phantomtouch.server.routes.touch import SCHEDULES
from phantomtouch.service import scheduling
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import responses
from phantomtouch.service.models import (
    JobAccepted,
    NamedTouch,
    PatternInfo,
    PlanSummary,
    PlayRequest,
)

router = APIRouter(prefix="/patterns", tags=["patterns"])

pattern_body, PATTERN_BODY_OPENAPI = strict_body(TypeAdapter(TouchPattern))
PatternBody = Annotated[TouchPattern, Depends(pattern_body)]
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


@library.get_item(router, TouchPattern, "One stored pattern", response_model_exclude_unset=True)
def get_pattern(name: PatternNameParam, store: StoreDep) -> TouchPattern:
    """The pattern as it was stored with `PUT`."""
    return scheduling.stored_pattern(store, name, field="name")


@library.put_item(router, PatternInfo, "Store a pattern", PATTERN_BODY_OPENAPI)
def put_pattern(name: PatternNameParam, pattern: PatternBody, service: ServiceDep) -> PatternInfo:
    """Store (or replace) a pattern; it is planned first, so only playable patterns are kept."""
    summary = scheduling.plan_summary(
        service.plans.plan(scheduling.with_clip(pattern, service.store))
    )
    service.store.put(name, pattern, summary)
    return PatternInfo(name=name, summary=PlanSummary(**summary))


@library.delete_item(router, "Remove a pattern")
def delete_pattern(name: PatternNameParam, store: StoreDep) -> Response:
    """Remove a stored pattern."""
    if not store.delete(name):
        raise library.not_stored(name, "in the pattern library (GET /patterns)")
    return Response(status_code=204)


@router.post(
    "/{name}/play", **SCHEDULES, summary="Play a stored pattern", openapi_extra=PLAY_BODY_OPENAPI
)
async def play_pattern(
    name: PatternNameParam,
    service: ServiceDep,
    timing: Annotated[PlayRequest, Depends(play_body)],
    source: SourceDep,
    arrival: ArrivalDep,
) -> JobAccepted:
    """As `POST /touch` with `{"stored": name}`; optional `start_in_ms` or `start_at_s`."""
    request = NamedTouch(stored=name, start_in_ms=timing.start_in_ms, start_at_s=timing.start_at_s)
    return await source.play(request, arrival=arrival)
