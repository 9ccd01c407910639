"""The wearer the output stage is fitted to: ``GET|PUT|DELETE /wearer``.

One mix feeds the output stage, so one stored wearer profile (one band of it) applies to
every touch, contact, OSC input and fleet request at a time
(:class:`~phantomtouch.service.wearers.ActiveWearer`). ``serve --wearer NAME`` chooses it
at start; ``PUT /wearer`` and a WebSocket ``hello`` that names a wearer choose another
while the service runs (the latest choice wins), from the next block on, ramped across
that block; ``DELETE /wearer`` takes it off.
"""

from __future__ import annotations

import math
from typing import Annotated

from fastapi import APIRouter, Depends, Response
from pydantic import TypeAdapter

from phantomtouch.server.deps import ServiceDep
from phantomtouch.server.routes import library
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import responses
from phantomtouch.service.running import Service
from phantomtouch.service.wearer_models import ActiveWearerInfo, WearerChoice

router = APIRouter(prefix="/wearer", tags=["wearers"])

EXAMPLE = {"name": "participant-07", "band": "sine_100hz"}
choice_body, CHOICE_BODY_OPENAPI = strict_body(TypeAdapter(WearerChoice))
CHOICE_BODY_OPENAPI["requestBody"]["content"]["application/json"]["example"] = EXAMPLE


def active_wearer(service: Service) -> ActiveWearerInfo:
    """The wearer in force and its per-channel offsets, dB."""
    choice = service.wearer.choice
    gains = service.wearer.gains
    return ActiveWearerInfo(
        name=None if choice is None else choice.name,
        band=None if choice is None else choice.band,
        offsets_db=[round(20.0 * math.log10(float(gain)), 6) for gain in gains],
    )


@router.get("", response_model=ActiveWearerInfo, responses=responses(401), summary="Wearer")
def get_active_wearer(service: ServiceDep) -> ActiveWearerInfo:
    """The wearer profile the output stage applies (`name`, `band`; null: none) and the
    offset it applies per output channel after the device's calibration (`GET /device`
    shows the calibration alone)."""
    return active_wearer(service)


@library.put_item(
    router, ActiveWearerInfo, "Choose the wearer", CHOICE_BODY_OPENAPI, path="", also=(429,)
)
def put_active_wearer(
    choice: Annotated[WearerChoice, Depends(choice_body)], service: ServiceDep
) -> ActiveWearerInfo:
    """Fit the output stage to the stored profile `name` (its band `band`, default
    `sine_100hz`) from the next block on, ramped over 20 ms, for everything the service
    plays. A name not in the library, or a profile naming a channel the device lacks, is
    refused (422, field `name`); more than 2 switches a second (after a burst of 5) are
    refused (429, naming the limit)."""
    service.wearer.choose(choice.name, choice.band)
    return active_wearer(service)


@router.delete("", status_code=204, responses=responses(401, 429, 503), summary="No wearer")
def delete_active_wearer(service: ServiceDep) -> Response:
    """Take the wearer off: the device's calibration alone from the next block on (a
    switch: more than 2 a second, after a burst of 5, are refused with 429)."""
    service.wearer.clear()
    return Response(status_code=204)
