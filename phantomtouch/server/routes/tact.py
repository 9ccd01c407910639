"""The ``.tact`` project library: ``GET /tact``, ``GET|PUT|DELETE /tact/{name}``, play.

A project (bHaptics Designer's ``.tact`` JSON: the file, or its ``project`` object) is
stored as ``phantomtouch import FILE.tact`` stores it, and played by ``POST
/tact/{name}/play`` (or the WebSocket's ``play`` with ``tact``) as the bHaptics stand-in
plays a registered key: each voice a job of the client (docs/bhaptics.md, ".tact files").
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Request, Response
from pydantic import TypeAdapter
from starlette.concurrency import run_in_threadpool

from phantomtouch.server.deps import (
    ArrivalDep,
    LimitParam,
    OffsetParam,
    ServiceDep,
    SourceDep,
    StoreDep,
)
from phantomtouch.server.routes import library
from phantomtouch.service import tact_library
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.document_library import TACT
from phantomtouch.service.errors import responses
from phantomtouch.service.models import PATTERN_NAME_REGEX, name_rules
from phantomtouch.service.tact_models import ScoreAccepted, TactInfo, TactPlay

router = APIRouter(prefix="/tact", tags=["patterns"])

TactNameParam = Annotated[str, Path(**name_rules(PATTERN_NAME_REGEX, "Stab_ArmL"))]
play_body, PLAY_BODY_OPENAPI = strict_body(
    TypeAdapter(TactPlay), required=False, default=TactPlay()
)
EXAMPLE: dict[str, Any] = {
    "project": {
        "name": "Stab_ArmL",
        "layout": {"type": "Tactosy2", "layouts": {}},
        "tracks": [
            {
                "enable": True,
                "effects": [
                    {
                        "startTime": 0,
                        "offsetTime": 300,
                        "modes": {
                            "ForearmL": {
                                "mode": "DOT_MODE",
                                "dotMode": {
                                    "dotConnected": False,
                                    "feedback": [
                                        {
                                            "startTime": 0,
                                            "endTime": 300,
                                            "playbackType": "FADE_OUT",
                                            "pointList": [{"index": 1, "intensity": 1.0}],
                                        }
                                    ],
                                },
                                "pathMode": {"feedback": []},
                            }
                        },
                    }
                ],
            }
        ],
    }
}
PROJECT_BODY_OPENAPI = library.document_body(
    "A bHaptics Designer `.tact` file, or its `project` object (`layout`, `tracks`); keys in "
    "any case, numbers also as strings (docs/bhaptics.md). It must have content for "
    "`ForearmL` or `ForearmR`.",
    EXAMPLE,
)


async def project_body(request: Request) -> tuple[str, Any]:
    """The body read as a project: its compact JSON and the project (422 naming the field
    if it is none, or has nothing for an arm)."""
    raw = await request.body()
    return await run_in_threadpool(tact_library.read_project, raw, source="body")


@library.list_items(router, TactInfo, "The .tact library")
def list_tact(store: StoreDep, limit: LimitParam = 100, offset: OffsetParam = 0) -> list[TactInfo]:
    """One page of the stored projects, sorted by name, with their size and length; fewer
    than `limit` means the last page. The projects themselves are not read."""
    return TACT.listed(store, limit=limit, offset=offset)


@library.get_document(router, "project", "One stored .tact project")
def get_tact(name: TactNameParam, store: StoreDep) -> Response:
    """The project as stored: the `.tact` JSON, compact, spelled as it was given."""
    return library.document(TACT.text(store, name))


@library.put_item(router, TactInfo, "Store a .tact project", PROJECT_BODY_OPENAPI)
def put_tact(
    name: TactNameParam,
    body: Annotated[tuple[str, Any], Depends(project_body)],
    store: StoreDep,
) -> TactInfo:
    """Store (or replace) a project; one with nothing for an arm is refused (422)."""
    text, project = body
    return TACT.put(store, name, text, tact_library.summary(project))


@library.delete_item(router, "Remove a .tact project")
def delete_tact(name: TactNameParam, store: StoreDep) -> Response:
    """Remove a stored project."""
    TACT.delete(store, name)
    return Response(status_code=204)


@router.post(
    "/{name}/play",
    status_code=202,
    response_model=ScoreAccepted,
    responses=responses(401, 404, 413, 415, 422, 429, 500, 503),
    summary="Play a stored .tact project",
    openapi_extra=PLAY_BODY_OPENAPI,
)
async def play_tact(
    name: TactNameParam,
    service: ServiceDep,
    request: Annotated[TactPlay, Depends(play_body)],
    source: SourceDep,
    arrival: ArrivalDep,
) -> ScoreAccepted:
    """Schedule every voice of the project as a job of this client, sample-exact to each
    other: whole, or not at all (429 `quota`). Optional `intensity_scale` and
    `duration_scale` (bHaptics' `scaleOption`), `start_in_ms` or `start_at_s`."""
    return await tact_library.play_tact(service, name, request, handle=source, arrival=arrival)
