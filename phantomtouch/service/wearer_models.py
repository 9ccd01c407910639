"""Answers and bodies of the wearer routes (``/wearers``, ``/wearer``): which profile the
output stage applies, in which band, and the gains that makes (``docs/wearer.md``)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from phantomtouch.schema.wearer import WEARER_NAME_REGEX, Band, WearerProfile


class WearerInfo(BaseModel):
    """A wearer profile of the library, and whether the output stage applies it."""

    name: str
    active: bool = Field(description="The output stage is fitted to this wearer now (GET /wearer).")
    profile: WearerProfile


class WearerChoice(BaseModel):
    """Which stored wearer profile the output stage applies, and in which band."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(
        min_length=1,
        max_length=64,
        pattern=WEARER_NAME_REGEX,
        description="A stored wearer profile (GET /wearers).",
    )
    band: Band = Field(
        default="sine_100hz",
        description="The carrier band of the profile to apply (one band for the whole mix).",
    )


class ActiveWearerInfo(BaseModel):
    """The wearer the output stage is fitted to, and the gains that makes per channel."""

    name: str | None = Field(description="The wearer profile in force, or null: none.")
    band: Band | None = Field(description="The band of that profile applied, or null.")
    offsets_db: list[float] = Field(
        description="Per output channel (index 0 is channel 1) the offset applied after the "
        "device's calibration, dB (all 0 without a wearer)."
    )
