"""The OSC map file: which avatar parameter is a contact receiver where on the forearm.

A TOML file (every key but ``receiver`` optional)::

    watchdog_s = 1.0          # a sender's silence this long releases its contacts
    threshold = 0.01          # proximity below this counts as untouched
    cluster_gap_cm = 6.2      # active receivers closer than this belong to one touch
    max_intensity = 0.6       # intensity at full proximity (1 = the device's max level)
    smoothing_s = 0.005       # time constant of the position and intensity smoothing
    carrier = {kind = "sine", freq_hz = 100}

    [[receiver]]
    address = "/avatar/parameters/PT_Arm_0"
    x_cm = 0.0
    y_cm = 0.0

Without a file, :func:`default_map` puts one receiver on each actuator of the device,
``/avatar/parameters/PT_Arm_0`` .. ``PT_Arm_7`` in the actuators' order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.errors import ParameterError
from phantomtouch.schema import DeviceProfile, limits
from phantomtouch.schema.pattern import Carrier, SineCarrier
from phantomtouch.schema.validation import read_model_file

MAX_RECEIVERS = 256
"""Receivers one map may place."""
MAX_SMOOTHING_S = 1.0 / 90.0
"""The smoothing may lag by at most one frame at 90 Hz (a one-pole lags a ramp by its
time constant)."""
DEFAULT_PREFIX = "/avatar/parameters/PT_Arm_"
"""Parameter names of :func:`default_map`: ``PT_Arm_0`` .. ``PT_Arm_{n-1}``."""


class Receiver(BaseModel):
    """One avatar contact receiver: its OSC address and where it sits on the forearm."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    address: str = Field(pattern=r"^/[!-~]{1,255}$", description="OSC address, e.g. /avatar/...")
    x_cm: float = Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM, allow_inf_nan=False)
    y_cm: float = Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM, allow_inf_nan=False)


class ReceiverMap(BaseModel):
    """Where the receivers are and how their proximities become contacts."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    receiver: list[Receiver] = Field(min_length=1, max_length=MAX_RECEIVERS)
    watchdog_s: float = Field(default=1.0, ge=0.05, le=30.0, allow_inf_nan=False)
    threshold: float = Field(default=0.01, ge=0.0, lt=1.0, allow_inf_nan=False)
    cluster_gap_cm: float = Field(default=6.2, gt=0.0, le=100.0, allow_inf_nan=False)
    max_intensity: float = Field(default=0.6, gt=0.0, le=1.0, allow_inf_nan=False)
    smoothing_s: float = Field(default=0.005, ge=0.0, le=MAX_SMOOTHING_S, allow_inf_nan=False)
    carrier: Carrier = Field(default_factory=SineCarrier)

    @model_validator(mode="after")
    def _unique(self) -> Self:
        seen: set[str] = set()
        for i, receiver in enumerate(self.receiver):
            if receiver.address in seen:
                raise ValueError(
                    f"receiver[{i}].address={receiver.address!r} appears twice; "
                    "each address places one receiver"
                )
            seen.add(receiver.address)
        return self

    @classmethod
    def load(cls, path: str | Path) -> ReceiverMap:
        """Read a map file (TOML).

        Raises
        ------
        ParameterError
            The file cannot be read, is not TOML, or a field is out of range (the
            message names the file and the field).
        """
        return read_model_file(
            cls, Path(path), what="OSC map", error=ParameterError, json_unless_toml=False
        )


def default_map(device: DeviceProfile) -> ReceiverMap:
    """One receiver on each actuator, ``PT_Arm_0`` on the first."""
    return ReceiverMap(
        receiver=[
            Receiver(address=f"{DEFAULT_PREFIX}{i}", x_cm=a.x_cm, y_cm=a.y_cm)
            for i, a in enumerate(device.actuators)
        ]
    )
