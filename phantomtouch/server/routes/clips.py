"""The clip library: ``GET /clips``, ``GET|PUT|DELETE /clips/{name}``.

A clip (amplitude and frequency envelopes, transients; ``phantomtouch import`` makes one
from a ``.haptic`` or ``.ahap`` file) is played as a pattern's carrier,
``{"kind": "clip", "clip": name}``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Response
from pydantic import TypeAdapter

from phantomtouch.schema import HapticClip
from phantomtouch.schema.clip import CLIP_NAME_REGEX
from phantomtouch.server.deps import LimitParam, OffsetParam, StoreDep
from phantomtouch.server.routes import library
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import responses
from phantomtouch.service.models import ClipInfo, name_rules

router = APIRouter(prefix="/clips", tags=["patterns"])

clip_body, CLIP_BODY_OPENAPI = strict_body(TypeAdapter(HapticClip))
ClipBody = Annotated[HapticClip, Depends(clip_body)]
ClipNameParam = Annotated[str, Path(**name_rules(CLIP_NAME_REGEX, "heartbeat"))]


def clip_info(name: str, clip: HapticClip) -> ClipInfo:
    return ClipInfo(
        name=name,
        duration_s=clip.duration_s,
        amplitude_points=len(clip.amplitude),
        frequency_points=len(clip.frequency),
        transients=len(clip.transients),
    )


@router.get("", response_model=list[ClipInfo], responses=responses(401, 422, 503), summary="Clips")
def list_clips(store: StoreDep, limit: LimitParam = 100, offset: OffsetParam = 0) -> list[ClipInfo]:
    """The stored clips with their duration and size, sorted by name, a page at a time:
    at most `limit` from the `offset`-th (a page shorter than `limit` is the last). The
    sizes are read without loading any clip."""
    return [
        ClipInfo(
            name=size.name,
            duration_s=size.duration_s,
            amplitude_points=size.amplitude_points,
            frequency_points=size.frequency_points,
            transients=size.transients,
        )
        for size in store.clip_sizes(limit=limit, offset=offset)
    ]


NOT_STORED = "in the clip library (GET /clips)"


@library.get_item(router, HapticClip, "One stored clip")
def get_clip(name: ClipNameParam, store: StoreDep) -> HapticClip:
    """The clip as it was stored."""
    return library.found(store.get_clip(name), name, NOT_STORED)


@library.put_item(router, ClipInfo, "Store a clip", CLIP_BODY_OPENAPI)
def put_clip(name: ClipNameParam, clip: ClipBody, store: StoreDep) -> ClipInfo:
    """Store (or replace) a clip; patterns that name it play the new one from now on."""
    store.put_clip(name, clip)
    return clip_info(name, clip)


@library.delete_item(router, "Remove a clip")
def delete_clip(name: ClipNameParam, store: StoreDep) -> Response:
    """Remove a stored clip (patterns that name it answer 404 until it is back)."""
    if not store.delete_clip(name):
        raise library.not_stored(name, NOT_STORED)
    return Response(status_code=204)
