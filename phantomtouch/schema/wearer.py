"""A wearer's profile: how much stronger or weaker each actuator is felt, per carrier band.

An accelerometer-calibrated armband gives the same acceleration on every actuator; a
person's skin does not feel it the same everywhere on the forearm. A profile holds, per
carrier band and per actuator, the offset in dB that makes that actuator felt as strong as
the reference actuator. The output stage multiplies each channel by
``10 ** (offset_db / 20)`` after the device's calibration, under the same safety ceiling.

Keys
----
Bands are named after the paper's two carriers:

- ``sine_100hz``: the 100 Hz sine;
- ``noise_40_500hz``: band-limited noise from 40 to 500 Hz.

Actuators are keyed by their sound-card output channel, 1-based (``"1"`` .. ``"8"`` on
the default armband), the index the device's calibration uses. A channel left out has
offset 0 dB. Which channels exist is the device's business: the service refuses a channel
its device does not have when the profile is stored (:func:`check_channels`).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StringConstraints,
    WithJsonSchema,
)

from phantomtouch.errors import ParameterError
from phantomtouch.schema.clip import CLIP_NAME_REGEX
from phantomtouch.schema.pattern import StrictJsonInt

MAX_OFFSET_DB = 20.0
"""Largest offset, either sign, dB."""
WEARER_NAME_REGEX = CLIP_NAME_REGEX
"""Letters, digits, '.', '_' and '-', 1 to 64 characters, not '.' or '..'."""
Band = Literal["sine_100hz", "noise_40_500hz"]
"""The carrier bands a profile is measured in."""
BANDS: tuple[Band, ...] = ("sine_100hz", "noise_40_500hz")
CHANNEL_REGEX = r"^(?:[1-9]|[1-5][0-9]|6[0-4])$"
"""An output channel as a JSON key: 1 to 64 (``limits.MAX_CHANNEL``), no leading zero."""
Channel = Annotated[str, StringConstraints(pattern=CHANNEL_REGEX)]
"""An actuator by its output channel, 1-based, as a JSON object key ("1" .. "64")."""
MAX_RUN_TRIALS = 4096
"""Most answers one matching run may hold (64 channels of 64 trials)."""
OffsetDb = Annotated[float, Field(ge=-MAX_OFFSET_DB, le=MAX_OFFSET_DB, allow_inf_nan=False)]
"""An offset in dB: finite, within ±``MAX_OFFSET_DB``."""
ChannelOffsets = Annotated[
    dict[Channel, OffsetDb],
    WithJsonSchema(
        {
            "type": "object",
            "patternProperties": {
                CHANNEL_REGEX: {
                    "type": "number",
                    "minimum": -MAX_OFFSET_DB,
                    "maximum": MAX_OFFSET_DB,
                }
            },
            "additionalProperties": False,
        }
    ),
]
"""One band's offsets by channel; the JSON Schema refuses any other key."""


class WearerProfile(BaseModel):
    """Offsets in dB per carrier band and per actuator (output channel, 1-based)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    offsets_db: dict[Band, ChannelOffsets] = Field(
        default_factory=dict,
        description=(
            "Per band (`sine_100hz`, `noise_40_500hz`), per output channel (1-based, "
            "as a string in JSON): the offset in dB added after the device's calibration, "
            f"finite, within ±{MAX_OFFSET_DB:g} dB. A channel or band left out is 0 dB."
        ),
        examples=[{"sine_100hz": {"1": 0.0, "2": 2.5, "3": -1.5}, "noise_40_500hz": {"2": 1.0}}],
    )
    note: str = Field(
        default="", max_length=500, description="Free text: who, when, which armband."
    )

    def channel_offsets_db(self, band: Band, channels: int) -> tuple[float, ...]:
        """Offsets of ``band`` for channels 1 .. ``channels`` (0 dB where none is given)."""
        given = self.offsets_db.get(band, {})
        return tuple(float(given.get(str(k), 0.0)) for k in range(1, channels + 1))


class WearerTrial(BaseModel):
    """One answered trial of the matching procedure: the test actuator, the level its
    interval was played at relative to the reference interval, and the wearer's answer."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    channel: StrictJsonInt = Field(ge=1, le=64, description="The test actuator's output channel.")
    level_db: OffsetDb = Field(
        description=(
            "Level of the test interval as played, dB re the reference interval, within "
            f"±{MAX_OFFSET_DB:g} dB (at most the device's max_level_db less the reference's)."
        )
    )
    test_stronger: StrictBool = Field(description="The wearer felt the test interval stronger.")


class WearerRun(BaseModel):
    """The answers of one matching run so far, stored as they come (``PUT
    /wearers/{name}/run``): a run that stops loses nothing and can be resumed."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    band: Band = Field(description="The carrier band the run matches in.")
    reference_channel: StrictJsonInt = Field(
        ge=1, le=64, description="The reference actuator's output channel."
    )
    trials: list[WearerTrial] = Field(
        default_factory=list,
        max_length=MAX_RUN_TRIALS,
        description=f"Every answered trial in the order asked, at most {MAX_RUN_TRIALS}.",
    )


def check_channels(profile: WearerProfile, channels: int) -> None:
    """Refuse a profile naming a channel a device of ``channels`` outputs does not have.

    Raises
    ------
    ParameterError
        The message starts with the first unknown actuator's field and offset, e.g.
        ``offsets_db.sine_100hz.9=2.0:``.
    """
    for band, given in profile.offsets_db.items():
        for channel in sorted(given, key=int):
            if int(channel) > channels:
                raise ParameterError(
                    f"offsets_db.{band}.{channel}={given[channel]!r}: this device has no "
                    f"actuator on channel {channel}; channels are 1 to {channels}"
                )


def check_run_channels(run: WearerRun, channels: int) -> None:
    """Refuse a run naming a channel a device of ``channels`` outputs does not have.

    Raises
    ------
    ParameterError
        Naming the first such field, e.g. ``trials[3].channel=9:``.
    """
    named = [("reference_channel", run.reference_channel)] + [
        (f"trials[{index}].channel", trial.channel) for index, trial in enumerate(run.trials)
    ]
    for field, channel in named:
        if channel > channels:
            raise ParameterError(
                f"{field}={channel}: this device has no actuator on channel {channel}; "
                f"channels are 1 to {channels}"
            )
