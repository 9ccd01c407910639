"""Offline rendering: ``POST /render`` answers the WAV, or the plan with its gain curves."""

from __future__ import annotations

from contextlib import ExitStack
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Header, Response
from fastapi.responses import StreamingResponse
from starlette.background import BackgroundTask

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.plan import Plan
from phantomtouch.renderer.trajectory import control_gains, positions_at
from phantomtouch.server.deps import ServiceDep
from phantomtouch.server.routes.touch import TOUCH_BODY_OPENAPI, TouchBody
from phantomtouch.server.wav import wav_bytes, wav_stream
from phantomtouch.service import scheduling
from phantomtouch.service.errors import responses
from phantomtouch.service.models import Curves, RenderPlan

router = APIRouter(tags=["render"])

MAX_CURVE_POINTS = 500
WAV_MEDIA_TYPE = "audio/wav"


def curves(plan: Plan, *, points: int = MAX_CURVE_POINTS) -> Curves:
    """Positions and channel gains (envelope included) at evenly spaced times."""
    n = int(min(points, max(2, plan.frames)))
    times_s = np.linspace(0.0, plan.duration_s, n, endpoint=False)
    positions, _ = positions_at(plan, times_s)
    gains = control_gains(plan, times_s)
    return Curves(
        times_s=np.round(times_s, 6).tolist(),
        positions_cm=[(float(x), float(y)) for x, y in np.round(positions, 4)],
        gains=np.round(gains, 6).tolist(),
    )


CLIPPED_HEADER = "X-Clipped-Fraction"
"""Response header of a WAV render: the fraction of its frames the safety ceiling clips, as
estimated before rendering (the WAV streams as it renders)."""


@router.post(
    "/render",
    response_model=RenderPlan,
    responses={
        200: {
            "description": (
                "A float32 WAV, one channel per actuator; with `Accept: application/json` "
                "the plan and its gain curves (at most 500 points)."
            ),
            "content": {WAV_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}}},
            "headers": {
                CLIPPED_HEADER: {
                    "description": "Fraction of the WAV's frames with a channel at the "
                    "safety ceiling (clipped), 0 to 1.",
                    "schema": {"type": "number", "minimum": 0, "maximum": 1},
                }
            },
        },
        **responses(401, 404, 413, 415, 422, 429, 500, 503),
    },
    summary="Render a touch offline",
    openapi_extra=TOUCH_BODY_OPENAPI,
)
def post_render(
    request: TouchBody,
    service: ServiceDep,
    accept: Annotated[str | None, Header(include_in_schema=False)] = None,
) -> Response | RenderPlan:
    """Render a touch request as the engine would play it (timing fields are ignored).

    WAV renders are capped at `max_render_duration_s` (default 600 s) and stream as they
    are rendered; a few run at once (`max_concurrent_renders`, each until its download
    ends or its client leaves), more are refused with 429.
    """
    pattern = scheduling.resolve(request, service.store)
    plan = service.plans.plan(pattern)
    if accept is not None and "application/json" in accept and WAV_MEDIA_TYPE not in accept:
        with service.render_slot():
            return RenderPlan(**scheduling.plan_summary(plan), curves=curves(plan))
    cap_s = service.settings.max_render_duration_s
    if plan.duration_s > cap_s:
        raise ParameterError(
            f"duration_s={plan.duration_s:.6g}: a WAV render lasts at most {cap_s:g} s "
            "(max_render_duration_s); ask with 'Accept: application/json' for the plan alone"
        )
    slot = ExitStack()
    slot.enter_context(service.render_slot())
    stream = wav_stream(plan, slot.close)
    return StreamingResponse(
        stream,
        background=BackgroundTask(stream.aclose),  # runs also when the client has left
        media_type=WAV_MEDIA_TYPE,
        headers={
            "Content-Disposition": 'attachment; filename="touch.wav"',
            CLIPPED_HEADER: f"{plan.clipped_fraction:.6g}",
            "Content-Length": str(wav_bytes(plan)),
        },
    )
