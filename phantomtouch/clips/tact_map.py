"""Where a bHaptics arm position's points land on the band: the arm map.

A Tactosy sleeve's layout is a unit square: ``x`` (three motor columns, 0, 0.5, 1) and
``y`` (two motor rows, 0 and 1). By default ``x`` runs along the band from its first ring
of actuators to its last (``y_cm`` from the smallest to the largest actuator ``y_cm``) and
``y`` around it from its first actuator column to its last (``x_cm`` likewise): the corner
``(0, 0)`` lands on the band's first actuator, dot index 2 (``x`` 1, ``y`` 0) at the band's
far end on its first column, and a path point at ``(x, y)`` is a phantom at exactly that
fraction of the band's actuator span. Both ``ForearmL`` and ``ForearmR`` play on the band
by default, at the same places. A small TOML file changes any of it::

    arms = ["ForearmL"]          # which arm positions play on this band (default both)
    max_intensity = 0.6          # a point of intensity 1 (100 in a frame): this much of
                                 # the device's max level
    carrier = {kind = "sine", freq_hz = 100}

    [ForearmL]                   # where three corners of the unit square land, cm
    origin_cm = [0.0, 0.0]       # (x 0, y 0)
    x_end_cm = [0.0, 14.4]       # (x 1, y 0)
    y_end_cm = [3.8, 0.0]        # (x 0, y 1)

The place of ``(x, y)`` is ``origin + x (x_end - origin) + y (y_end - origin)``: any
flip, swap or inset of the square is three corners. docs/bhaptics.md ("The mapping") has
a picture.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.clips.tact import TACTOSY2_LAYOUT
from phantomtouch.schema import DeviceProfile
from phantomtouch.schema.pattern import Carrier, Law, Point, SineCarrier
from phantomtouch.schema.validation import TomlFileModel

ArmName = Literal["ForearmL", "ForearmR"]


def _both_arms() -> list[ArmName]:
    return ["ForearmL", "ForearmR"]


class ArmPlacement(BaseModel):
    """Where the corners ``(0, 0)``, ``(1, 0)`` and ``(0, 1)`` of an arm's unit square land."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    origin_cm: Point = Field(description="Where x = 0, y = 0 lands (x_cm, y_cm).")
    x_end_cm: Point = Field(description="Where x = 1, y = 0 lands.")
    y_end_cm: Point = Field(description="Where x = 0, y = 1 lands.")

    def place(self, x: float, y: float) -> tuple[float, float]:
        """The band coordinates (x_cm, y_cm) of the layout point ``(x, y)``, each 0-1."""
        ox, oy = self.origin_cm
        ax, ay = self.x_end_cm
        bx, by = self.y_end_cm
        return (ox + x * (ax - ox) + y * (bx - ox), oy + x * (ay - oy) + y * (by - oy))


def span_placement(device: DeviceProfile) -> ArmPlacement:
    """The default: ``x`` along the band's actuator span (``y_cm``), ``y`` around it."""
    xs = [a.x_cm for a in device.actuators]
    ys = [a.y_cm for a in device.actuators]
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    return ArmPlacement(origin_cm=(x0, y0), x_end_cm=(x0, y1), y_end_cm=(x1, y0))


class ArmMap(TomlFileModel):
    """Which arm positions play on the band, where, and how strongly (a file of its own:
    :meth:`~phantomtouch.schema.validation.TomlFileModel.load`)."""

    FILE_KIND = "bHaptics arm map"
    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)

    arms: list[ArmName] = Field(
        default_factory=_both_arms,
        min_length=1,
        max_length=2,
        description="The arm positions this band plays; the others play nothing.",
    )
    max_intensity: float = Field(default=0.6, gt=0.0, le=1.0, allow_inf_nan=False)
    carrier: Carrier = Field(default_factory=SineCarrier)
    law: Law = "power"
    forearm_l: ArmPlacement | None = Field(default=None, alias="ForearmL")
    forearm_r: ArmPlacement | None = Field(default=None, alias="ForearmR")

    @model_validator(mode="after")
    def _unique(self) -> Self:
        if len(set(self.arms)) != len(self.arms):
            raise ValueError(f"arms={self.arms!r} names an arm twice")
        return self

    def placement(self, position: str, device: DeviceProfile) -> ArmPlacement | None:
        """Where ``position``'s unit square lands on ``device``; None: it plays nothing here."""
        if position not in self.arms:
            return None
        given = self.forearm_l if position == "ForearmL" else self.forearm_r
        return given if given is not None else span_placement(device)

    def point_cm(
        self, device: DeviceProfile, position: str, x: float, y: float
    ) -> tuple[float, float] | None:
        """Band coordinates of a path point ``(x, y)`` (clamped to 0-1) of ``position``.

        Returns None for a position this band does not play (vest, head, hands, feet, an
        arm left out of ``arms``). Any thread.
        """
        placement = self.placement(position, device)
        if placement is None:
            return None
        return placement.place(min(1.0, max(0.0, x)), min(1.0, max(0.0, y)))

    def dot_cm(
        self,
        device: DeviceProfile,
        position: str,
        index: int,
        layout: Mapping[int, tuple[float, float]] | None = None,
    ) -> tuple[float, float] | None:
        """Band coordinates of motor ``index`` of ``position`` (None: not played here).

        ``layout`` is the project's ``index -> (x, y)`` (default: Tactosy for arms); an
        index it does not hold plays nothing (bHapticsLib sends 20 slots for 6 motors).
        """
        spot = (layout if layout is not None else TACTOSY2_LAYOUT).get(index)
        if spot is None:
            return None
        return self.point_cm(device, position, *spot)
