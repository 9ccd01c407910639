"""Haptic clips: what a touch feels like over time, played as a pattern's carrier.

A clip is an amplitude envelope and a frequency envelope, each a list of breakpoints
joined by straight lines, and transients (short clicks) at given times. Values are 0-1
as in the formats clips come from (Meta Haptics Studio's ``.haptic``, Apple's ``.ahap``,
see :mod:`phantomtouch.clips`); the renderer maps frequency 0-1 onto the actuator's band
(docs/algorithms.md, sec. 11). A pattern plays a clip with the carrier
``{"kind": "clip", "clip": "name"}``: the clip decides what the touch feels like, the
pattern's path where it is felt.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.schema.validation import check_never_decreasing

MAX_CLIP_S = 600.0
"""Longest clip, s."""
MIN_CLIP_S = 0.001
"""Shortest clip, s (48 frames at 48 kHz). A looped clip starts again every
``duration_s``; a shorter one has no sample of its own (5e-324 s made every sample NaN)."""
MAX_CLIP_TRANSIENTS = 1000
"""Most transients of one clip (a click every 0.6 s through the longest clip). The renderer
renders them once, when the clip is planned, into a table of at most 60 ms each (11.5 MB
of float32 at 48 kHz for a thousand apart)."""
MAX_CLIP_POINTS = 100_000
"""Most breakpoints of one envelope, and most transients."""
CLIP_NAME_REGEX = (
    r"^(?:[A-Za-z0-9_-][A-Za-z0-9._-]{0,63}"
    r"|\.[A-Za-z0-9_-][A-Za-z0-9._-]{0,62}"
    r"|\.\.[A-Za-z0-9._-]{1,62})$"
)
"""Clip names follow the pattern library's rule: 1-64 letters, digits, '.', '_', '-', not
'.' or '..'."""

ClipName = Annotated[
    str,
    Field(
        min_length=1,
        max_length=64,
        pattern=CLIP_NAME_REGEX,
        description="A clip in the library (GET /clips); 1-64 letters, digits, '.', '_', '-'.",
    ),
]
Unit = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
ClipTime = Annotated[float, Field(ge=0.0, le=MAX_CLIP_S, allow_inf_nan=False)]


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Breakpoint(_Model):
    """The envelope's value at ``t_s``; between breakpoints it is a straight line."""

    t_s: ClipTime
    value: Unit


class Transient(_Model):
    """A short click at ``t_s``: three cycles at ``frequency`` under a Hann window."""

    t_s: ClipTime
    amplitude: Unit
    frequency: Unit = Field(description="0-1, mapped onto the actuator's band like the envelope.")


class HapticClip(_Model):
    """An amplitude envelope, a frequency envelope and transients, all 0-1.

    Equal times in an envelope make a step. Before the first breakpoint an envelope holds
    its first value, after the last its last value, until ``duration_s``.
    """

    duration_s: float = Field(ge=MIN_CLIP_S, le=MAX_CLIP_S, allow_inf_nan=False)
    amplitude: list[Breakpoint] = Field(min_length=1, max_length=MAX_CLIP_POINTS)
    frequency: list[Breakpoint] = Field(
        default_factory=lambda: [Breakpoint(t_s=0.0, value=0.5)],
        min_length=1,
        max_length=MAX_CLIP_POINTS,
    )
    transients: list[Transient] = Field(default_factory=list, max_length=MAX_CLIP_TRANSIENTS)

    @model_validator(mode="after")
    def _times(self) -> Self:
        check_never_decreasing([p.t_s for p in self.amplitude], "amplitude", time_name="t_s")
        check_never_decreasing([p.t_s for p in self.frequency], "frequency", time_name="t_s")
        check_never_decreasing([p.t_s for p in self.transients], "transients", time_name="t_s")
        return self


def _clip_carrier_schema(schema: dict[str, Any]) -> None:
    """``kind`` is required on the wire, as for the other carriers, its default aside;
    and ``clip``, ``data`` or both."""
    schema["required"] = ["kind", *schema.get("required", [])]
    given = {"not": {"type": "null"}}
    schema["anyOf"] = [
        {"required": [name], "properties": {name: given}} for name in ("clip", "data")
    ]


class ClipCarrier(_Model):
    """A haptic clip as the carrier (it brings its own envelope): the library's clip
    named ``clip``, or the clip itself in ``data`` (with or without a name).

    The service fills in ``data`` from the library when the pattern is played or
    rendered; ``phantomtouch render`` does so from ``--db``, or plays ``data`` alone.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", json_schema_extra=_clip_carrier_schema)

    kind: Literal["clip"] = "clip"
    clip: ClipName | None = Field(
        default=None, description="A clip of the library; optional when data is given."
    )
    loop: bool = Field(
        default=False,
        description="Repeat the clip while the pattern lasts (else once, then silence).",
    )
    data: HapticClip | None = Field(
        default=None, description="The clip itself; omitted, the library's clip of that name."
    )

    @model_validator(mode="after")
    def _named_or_given(self) -> Self:
        if self.clip is None and self.data is None:
            raise ValueError(
                "a clip carrier needs clip (the name of a clip in the library) or data "
                "(the clip itself, as phantomtouch import -o writes it)"
            )
        return self
