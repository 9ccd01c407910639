"""Offline rendering: ``POST /render`` answers the WAV, or the plan with its gain curves."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from typing import IO, Annotated

import numpy as np
import soundfile
from fastapi import APIRouter, Header, Response
from fastapi.responses import StreamingResponse

from phantomtouch.errors import ParameterError
from phantomtouch.renderer import render_plan_blocks
from phantomtouch.renderer.output import frames_at_ceiling
from phantomtouch.renderer.plan import Plan
from phantomtouch.renderer.trajectory import control_gains, positions_at
from phantomtouch.server import touch
from phantomtouch.server.deps import ServiceDep
from phantomtouch.server.errors import responses
from phantomtouch.server.models import Curves, RenderPlan
from phantomtouch.server.routes.touch import TOUCH_BODY_OPENAPI, TouchBody

router = APIRouter(tags=["render"])

MAX_CURVE_POINTS = 500
_WAV_BLOCK_FRAMES = 1 << 15
_SPOOL_BYTES = 16 << 20
_CHUNK_BYTES = 1 << 20
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
"""Response header of a WAV render: the fraction of its frames at the safety ceiling."""


def _wav_file(plan: Plan) -> tuple[IO[bytes], float]:
    spool = tempfile.SpooledTemporaryFile(max_size=_SPOOL_BYTES)  # noqa: SIM115 (streamed, closed by _chunks)
    with soundfile.SoundFile(
        spool,
        "w",
        samplerate=plan.sample_rate_hz,
        channels=plan.channels,
        subtype="FLOAT",
        format="WAV",
    ) as wav:
        clipped = 0
        for block in render_plan_blocks(plan, block_frames=_WAV_BLOCK_FRAMES):
            wav.write(block)
            clipped += frames_at_ceiling(block, plan.device.safety.ceiling)
    spool.seek(0)
    return spool, clipped / plan.frames


def _chunks(file: IO[bytes]) -> Iterator[bytes]:
    with file:
        while chunk := file.read(_CHUNK_BYTES):
            yield chunk


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
        **responses(401, 404, 413, 415, 422, 429, 500),
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

    WAV renders are capped at `max_render_duration_s` (default 600 s); a few run at once
    (`max_concurrent_renders`), more are refused with 429.
    """
    pattern = touch.resolve(request, service.store)
    plan = service.plans.plan(pattern)
    if accept is not None and "application/json" in accept and WAV_MEDIA_TYPE not in accept:
        with service.render_slot():
            return RenderPlan(**touch.plan_summary(plan), curves=curves(plan))
    cap_s = service.settings.max_render_duration_s
    if plan.duration_s > cap_s:
        raise ParameterError(
            f"duration_s={plan.duration_s:.6g}: a WAV render lasts at most {cap_s:g} s "
            "(max_render_duration_s); ask with 'Accept: application/json' for the plan alone"
        )
    with service.render_slot():
        wav, clipped_fraction = _wav_file(plan)
    return StreamingResponse(
        _chunks(wav),
        media_type=WAV_MEDIA_TYPE,
        headers={
            "Content-Disposition": 'attachment; filename="touch.wav"',
            CLIPPED_HEADER: f"{clipped_fraction:.6g}",
        },
    )
