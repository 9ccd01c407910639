"""Bodies of the ``.tact`` project library: ``/tact``, and ``play`` naming a project."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from phantomtouch.clips.tact_score import MAX_SCALE, MIN_DURATION_SCALE
from phantomtouch.service.models import PATTERN_NAME_REGEX, Timing, name_rules

TactName = Annotated[str, Field(**name_rules(PATTERN_NAME_REGEX, "Stab_ArmL"))]


class TactPlay(Timing):
    """How to play a stored project: its ``scaleOption`` and optional timing."""

    intensity_scale: float = Field(
        default=1.0,
        ge=0.0,
        le=MAX_SCALE,
        allow_inf_nan=False,
        description="Multiplies every intensity of the project (clamped to full), as a "
        "bHaptics `scaleOption.intensity`.",
    )
    duration_scale: float = Field(
        default=1.0,
        ge=MIN_DURATION_SCALE,
        le=MAX_SCALE,
        allow_inf_nan=False,
        description="Stretches the project in time (2: twice as long), as a bHaptics "
        "`scaleOption.duration`.",
    )


class TactInfo(BaseModel):
    """A stored ``.tact`` project: its name, size and what it plays on."""

    name: str
    bytes: int = Field(description="Size of the stored project JSON, bytes.")
    duration_s: float = Field(description="The project's length (its latest effect end), s.")
    positions: list[str] = Field(
        description="The bHaptics positions it has content for (`ForearmL`, `VestFront` ...)."
    )
    effects: int = Field(description="Effects of its enabled tracks.")


class ScoreAccepted(BaseModel):
    """A stored project scheduled on the engine: one job per voice."""

    name: str
    job_ids: list[str] = Field(
        description="One job per voice (`GET|DELETE /jobs/{id}`); all stop with `POST /stop`."
    )
    start_at_s: float = Field(description="Server time of the project's time 0, s.")
    start_frame: int = Field(description="Engine frame of the project's time 0.")
    duration_s: float = Field(description="The project's length times `duration_scale`, s.")

    model_config = {
        "json_schema_extra": {
            "examples": [
                {
                    "name": "Stab_ArmL",
                    "job_ids": ["3e366f948de94b6fb2f78bf2ce4243c8"],
                    "start_at_s": 1234.52,
                    "start_frame": 59256960,
                    "duration_s": 0.3,
                }
            ]
        }
    }
