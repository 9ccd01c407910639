"""The bHaptics SDK2 workspace library: ``GET /bhaptics/workspaces``, ``GET|PUT|DELETE
/bhaptics/workspaces/{workspace_id}``.

A workspace is a game's deployment (the Developer Portal's JSON: its events by name),
stored under the id the game connects with, as ``phantomtouch import DEPLOYMENT.json``
stores it; the SDK2 stand-in plays its events by name (docs/bhaptics.md, "SDK2").
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Request, Response
from starlette.concurrency import run_in_threadpool

from phantomtouch.clips.deployment import Deployment
from phantomtouch.errors import FieldError
from phantomtouch.server.deps import LimitParam, OffsetParam, StoreDep
from phantomtouch.server.routes import library
from phantomtouch.service import workspace_library
from phantomtouch.service.document_library import WORKSPACES
from phantomtouch.service.models import PATTERN_NAME_REGEX, name_rules
from phantomtouch.service.workspace_models import WORKSPACE_EXAMPLE, WorkspaceInfo

router = APIRouter(prefix="/bhaptics/workspaces", tags=["bhaptics"])

WorkspaceIdParam = Annotated[str, Path(**name_rules(PATTERN_NAME_REGEX, WORKSPACE_EXAMPLE))]
EXAMPLE: dict[str, Any] = {
    "status": True,
    "code": 200,
    "errorMessage": None,
    "timestamp": 1694710443550,
    "message": {
        "name": "A Game",
        "workspaceId": WORKSPACE_EXAMPLE,
        "version": 3,
        "hapticMappings": [
            {
                "key": "recoil_r",
                "enable": True,
                "intensity": 100,
                "eventTime": 100,
                "tactFilePatterns": [],
                "audioFilePatterns": [
                    {
                        "position": "Vest",
                        "clip": {
                            "patterns": {
                                "ForearmR": [
                                    "ZGRkZGRkAAAAAAAAAAAAAAAAAAA=",
                                    "MjIyMjIyAAAAAAAAAAAAAAAAAAA=",
                                ]
                            }
                        },
                    }
                ],
            }
        ],
    },
}
DEPLOYMENT_BODY_OPENAPI = library.document_body(
    "A game's deployment: the bHaptics Developer Portal's answer (`{status, message: "
    "{hapticMappings: [...]}}`) or its `message`; each mapping an event (`key`) with "
    "`tactFilePatterns` (.tact projects) and `audioFilePatterns` (base64 frames of 20 motor "
    "levels every 20 ms); keys in any case (docs/bhaptics.md, SDK2).",
    EXAMPLE,
)


async def deployment_body(request: Request) -> tuple[str, Deployment]:
    """The body read as a deployment: its compact JSON and the deployment (422 naming the
    field at fault if it is none)."""
    text, deployment = await run_in_threadpool(
        workspace_library.read_deployment, await request.body()
    )
    if not text.startswith("{"):
        raise FieldError(
            "the body must be a JSON object: the Developer Portal's answer or its message",
            field="body",
        )
    return text, deployment


@library.list_items(router, WorkspaceInfo, "The bHaptics SDK2 workspaces")
def list_workspaces(
    store: StoreDep, limit: LimitParam = 100, offset: OffsetParam = 0
) -> list[WorkspaceInfo]:
    """One page of the stored workspaces, sorted by id, with their game, size and events;
    fewer than `limit` means the last page. The deployments themselves are not read."""
    return WORKSPACES.listed(store, limit=limit, offset=offset)


@library.get_document(
    router, "deployment", "One stored workspace's deployment", path="/{workspace_id}"
)
def get_workspace(workspace_id: WorkspaceIdParam, store: StoreDep) -> Response:
    """The deployment as stored: the JSON, compact, spelled as it was given."""
    return library.document(WORKSPACES.text(store, workspace_id))


@library.put_item(
    router,
    WorkspaceInfo,
    "Store a game's deployment for a workspace",
    DEPLOYMENT_BODY_OPENAPI,
    path="/{workspace_id}",
)
def put_workspace(
    workspace_id: WorkspaceIdParam,
    body: Annotated[tuple[str, Deployment], Depends(deployment_body)],
    store: StoreDep,
) -> WorkspaceInfo:
    """Store (or replace) the deployment of a workspace: a game connecting with this
    `workspace_id` plays its events by name. The id in the path decides, whatever the
    deployment's own `workspaceId` says."""
    text, deployment = body
    return WORKSPACES.put(store, workspace_id, text, workspace_library.summary(deployment))


@library.delete_item(router, "Remove a workspace", path="/{workspace_id}")
def delete_workspace(workspace_id: WorkspaceIdParam, store: StoreDep) -> Response:
    """Remove a stored workspace: its events are no longer known."""
    WORKSPACES.delete(store, workspace_id)
    return Response(status_code=204)
