"""Bodies of the bHaptics SDK2 workspace library: ``/bhaptics/workspaces``."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from phantomtouch.service.models import PATTERN_NAME_REGEX, name_rules

WORKSPACE_EXAMPLE = "67b7bacf3213f135c2f1580e"
"""A workspace id as the Developer Portal makes them (24 hex digits; older: 20 letters)."""
WorkspaceId = Annotated[str, Field(**name_rules(PATTERN_NAME_REGEX, WORKSPACE_EXAMPLE))]


class WorkspaceInfo(BaseModel):
    """A stored workspace: a game's deployment, summarised."""

    workspace_id: str = Field(
        description="The id a game connects with (`workspace_id` of `/v3/feedback`)."
    )
    game: str = Field(description="The deployment's `name` ('' when it has none).")
    version: int | None = Field(description="The deployment's `version` (null: not given).")
    bytes: int = Field(description="Size of the stored deployment JSON, bytes.")
    events: int = Field(description="Its events (enabled mappings).")
    arm_events: int = Field(
        description="Of them, those with content on `ForearmL` or `ForearmR`: what an arm "
        "band plays; the others are answered and play nothing here."
    )
    longest_ms: int = Field(description="The longest event's length, ms.")

    model_config = {
        "json_schema_extra": {
            "examples": [
                {
                    "workspace_id": WORKSPACE_EXAMPLE,
                    "game": "A Game",
                    "version": 22,
                    "bytes": 196896,
                    "events": 35,
                    "arm_events": 17,
                    "longest_ms": 5220,
                }
            ]
        }
    }
