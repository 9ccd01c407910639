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
``/avatar/parameters/PT_Arm_0`` .. ``PT_Arm_7`` in the actuators' order. The map named
``bhaptics`` (:func:`bhaptics_map`) takes a bHapticsOSC avatar's twelve arm parameters as
they are, each on its Tactosy motor's place on the band.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.clips.tact import TACTOSY2_LAYOUT
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.schema import DeviceProfile, limits
from phantomtouch.schema.pattern import Carrier, SineCarrier
from phantomtouch.schema.validation import TomlFileModel

MAX_RECEIVERS = 256
"""Receivers one map may place."""
MAX_SMOOTHING_S = 1.0 / 90.0
"""The smoothing may lag by at most one frame at 90 Hz (a one-pole lags a ramp by its
time constant)."""
DEFAULT_PREFIX = "/avatar/parameters/PT_Arm_"
"""Parameter names of :func:`default_map`: ``PT_Arm_0`` .. ``PT_Arm_{n-1}``."""
BHAPTICS_MAP = "bhaptics"
"""The name ``--map`` takes for :func:`bhaptics_map` (a file of that name wins)."""
BHAPTICS_PREFIX = "/avatar/parameters/bHapticsOSC_Arm_"
"""bHapticsOSC's arm parameters: ``{prefix}Left_1`` .. ``_6`` and ``{prefix}Right_1`` .. ``_6``."""
_BHAPTICS_SIDES = {"ForearmL": "Left", "ForearmR": "Right"}


class Receiver(BaseModel):
    """One avatar contact receiver: its OSC address and where it sits on the forearm."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    address: str = Field(pattern=r"^/[!-~]{1,255}$", description="OSC address, e.g. /avatar/...")
    x_cm: float = Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM, allow_inf_nan=False)
    y_cm: float = Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM, allow_inf_nan=False)


class ReceiverMap(TomlFileModel):
    """Where the receivers are and how their proximities become contacts (a file of its
    own: :meth:`~phantomtouch.schema.validation.TomlFileModel.load`)."""

    FILE_KIND = "OSC map"
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


def default_map(device: DeviceProfile) -> ReceiverMap:
    """One receiver on each actuator, ``PT_Arm_0`` on the first."""
    return ReceiverMap(
        receiver=[
            Receiver(address=f"{DEFAULT_PREFIX}{i}", x_cm=a.x_cm, y_cm=a.y_cm)
            for i, a in enumerate(device.actuators)
        ]
    )


def bhaptics_map(device: DeviceProfile, arm_map: ArmMap | None = None) -> ReceiverMap:
    """A bHapticsOSC avatar's arm parameters, each on its motor's place on the band.

    ``bHapticsOSC_Arm_Left_k`` and ``bHapticsOSC_Arm_Right_k`` (k = 1 .. 6) are Tactosy
    motor index ``k - 1`` of ``ForearmL`` and ``ForearmR``, placed by ``arm_map`` (default:
    both arms on the whole band, docs/bhaptics.md "The mapping"); an arm the map leaves
    out has no receivers. Receivers one motor step apart along or around the band are
    neighbours, so a hand between two motors is one phantom between them.
    """
    arm_map = arm_map or ArmMap()
    receivers = []
    spacing_cm = 0.0
    for arm in arm_map.arms:
        side = _BHAPTICS_SIDES[arm]
        for index in sorted(TACTOSY2_LAYOUT):
            spot = arm_map.dot_cm(device, arm, index)
            assert spot is not None  # an arm of the map plays on the band
            receivers.append(
                Receiver(address=f"{BHAPTICS_PREFIX}{side}_{index + 1}", x_cm=spot[0], y_cm=spot[1])
            )
        placement = arm_map.placement(arm, device)
        assert placement is not None
        corner = placement.place(0.0, 0.0)
        along = placement.place(0.5, 0.0)
        around = placement.place(0.0, 1.0)
        spacing_cm = max(
            spacing_cm,
            math.dist(corner, along),
            math.dist(corner, around),
        )
    gap_cm = min(100.0, max(0.1, 1.05 * spacing_cm))
    return ReceiverMap(
        receiver=receivers,
        cluster_gap_cm=gap_cm,
        max_intensity=arm_map.max_intensity,
        carrier=arm_map.carrier,
    )


def load_map(path: Path | None, device: DeviceProfile) -> ReceiverMap:
    """The OSC map ``--map`` names: a TOML file, ``bhaptics`` (:func:`bhaptics_map`, unless
    a file of that name exists), or None for :func:`default_map`.

    Raises
    ------
    ParameterError
        The file cannot be read or is invalid.
    """
    if path is None:
        return default_map(device)
    if str(path) == BHAPTICS_MAP and not path.exists():
        return bhaptics_map(device)
    return ReceiverMap.load(path)
