"""Device profile: where the actuators sit, how they are wired, calibrated and limited.

The default profile is the armband of Kirchner et al. (IEEE ToH 2023): 8 actuators in
4 rows along the forearm (y, 4.8 cm apart) and 2 columns around it (x, 3.8 cm apart).
Actuators 1-4 form the column at x = 0 cm (the right side of the left forearm),
actuators 5-8 the column at x = 3.8 cm; actuators 1 and 5 face the hand (y = 0 cm),
4 and 8 the elbow (y = 14.4 cm). Channel k drives actuator k.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema import limits
from phantomtouch.schema.validation import read_model_file

if TYPE_CHECKING:
    import numpy as np

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Coordinate = Annotated[float, Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM)]
LevelDb = Annotated[
    float, Field(ge=limits.MIN_LEVEL_DB, le=limits.MAX_LEVEL_DB, allow_inf_nan=False)
]
"""An acceleration level, dB re 1 µm/s² (RMS), within the limits any profile allows."""

_ROWS_Y_CM = (0.0, 4.8, 9.6, 14.4)
"""Rows along the forearm, 4.8 cm apart (written out so 14.4 is exact, not 3 x 4.8)."""
_COLUMNS_X_CM = (0.0, 3.8)
_MIN_ACTUATOR_DISTANCE_CM = 0.1
DEFAULT_GAIN_UPDATE_S = 128 / 48000
"""Default time between two gain computations: 128 frames at 48 kHz, 2.67 ms."""
_MIN_TRIANGLE_AREA_CM2 = 1e-3


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Actuator(_Frozen):
    """One actuator: its position on the skin and the sound-card output that drives it."""

    x_cm: Coordinate = Field(description="Position around the forearm, cm.")
    y_cm: Coordinate = Field(description="Position along the forearm (0 = wrist end), cm.")
    channel: int = Field(
        ge=1, le=limits.MAX_CHANNEL, description="Sound-card output number, 1-based."
    )


class Calibration(_Frozen):
    """How drive amplitude maps to acceleration on the skin, per output channel.

    A voice renders its signal relative to ``reference_level_db``: amplitude 1.0 is a
    sine that gives that level. The mixer then scales each channel by
    ``10 ** ((reference_level_db - channel_level_db[k]) / 20)`` so that a weaker
    actuator gets more drive, and applies the optional FIR correction.
    """

    reference_level_db: LevelDb = Field(
        default=155.0,
        description=(
            "RMS acceleration level, dB re 1 µm/s², of a full-scale sine (amplitude 1.0) "
            "on a nominal channel. The default is an assumption for a Lofelt L5 on skin."
        ),
    )
    channel_level_db: tuple[float, ...] | None = Field(
        default=None,
        description=(
            "Per output channel (index 0 = channel 1): level, dB re 1 µm/s², that a "
            "full-scale sine gives on that channel. None: every channel is nominal."
        ),
    )
    fir_taps: tuple[tuple[FiniteFloat, ...], ...] | None = Field(
        default=None,
        description="Per output channel: FIR correction taps (applied after the mix).",
    )

    @model_validator(mode="after")
    def _check_levels(self) -> Self:
        for k, level_db in enumerate(self.channel_level_db or ()):
            if not limits.MIN_LEVEL_DB <= level_db <= limits.MAX_LEVEL_DB:
                raise ValueError(
                    f"channel_level_db[{k}]={level_db!r} must be within "
                    f"[{limits.MIN_LEVEL_DB}, {limits.MAX_LEVEL_DB}] dB"
                )
        for k, taps in enumerate(self.fir_taps or ()):
            if not 1 <= len(taps) <= limits.MAX_FIR_TAPS:
                raise ValueError(
                    f"fir_taps[{k}] has {len(taps)} taps; 1 to {limits.MAX_FIR_TAPS} allowed"
                )
        return self


class SafetyLimits(_Frozen):
    """Limits that protect the wearer and the actuators."""

    max_level_db: LevelDb = Field(
        default=150.0,
        description=(
            "Strongest acceleration level, dB re 1 µm/s², a pattern may ask for; "
            "relative intensity 1.0 means this level."
        ),
    )
    ceiling: float = Field(
        default=1.0,
        gt=0.0,
        le=1.0,
        description="Largest absolute sample value on any output channel (full scale = 1).",
    )


def _point(position: np.ndarray) -> str:
    return f"({position[0]:.6g}, {position[1]:.6g})"


def _paper_actuators() -> tuple[Actuator, ...]:
    return tuple(
        Actuator(x_cm=x_cm, y_cm=y_cm, channel=column * len(_ROWS_Y_CM) + row + 1)
        for column, x_cm in enumerate(_COLUMNS_X_CM)
        for row, y_cm in enumerate(_ROWS_Y_CM)
    )


def _paper_triangles() -> tuple[tuple[int, int, int], ...]:
    """Two triangles per grid cell, cut by one fixed diagonal (lower left to upper right)."""
    triangles = []
    for row in range(3):
        a, b = row, row + 1  # column 0 (actuators 1-4), indices into the actuator list
        c, d = 4 + row, 4 + row + 1  # column 1 (actuators 5-8)
        triangles.append((a, c, d))
        triangles.append((a, d, b))
    return tuple(triangles)


class DeviceProfile(_Frozen):
    """An actuator layout with its wiring, timing, calibration and safety limits.

    ``DeviceProfile.default()`` is the paper's armband and needs no file. Custom layouts
    load from TOML or JSON (:meth:`load`); without ``triangles`` they are triangulated
    with Delaunay. Duplicate or collinear actuators are refused.
    """

    name: str = Field(default="kirchner2023-armband", min_length=1, max_length=100)
    actuators: tuple[Actuator, ...] = Field(
        default_factory=_paper_actuators, min_length=3, max_length=limits.MAX_ACTUATORS
    )
    triangles: tuple[tuple[int, int, int], ...] | None = Field(
        default=None,
        description=(
            "Triangles as indices into `actuators`. None: the paper's fixed diagonals when "
            "`actuators` is left at its default, else a Delaunay triangulation."
        ),
    )
    sample_rate_hz: int = Field(
        default=48000, ge=limits.MIN_SAMPLE_RATE_HZ, le=limits.MAX_SAMPLE_RATE_HZ
    )
    block_frames: int = Field(
        default=256,
        ge=limits.MIN_BLOCK_FRAMES,
        le=limits.MAX_BLOCK_FRAMES,
        description=(
            "Frames per audio block of the real-time engine where its output has no period "
            "of its own (the null and capture outputs, host APIs without a fixed buffer); "
            "on JACK, ASIO, Core Audio and WASAPI the engine's block is the sound card's "
            "period instead (`GET /device` shows both)."
        ),
    )
    gain_update_s: float = Field(
        default=DEFAULT_GAIN_UPDATE_S,
        gt=0.0,
        le=limits.MAX_GAIN_UPDATE_S,
        description=(
            "Time between two gain computations along a path, s; the renderer rounds it "
            "to whole frames of the sample rate (at least 1). The default, 2.67 ms (128 "
            "frames at 48 kHz) with ramps, is the cheapest setting that `phantomtouch bench "
            "accuracy` finds within a tenth of the perceptual thresholds: on a 100 cm/s "
            "zig-zag the phantom stays within 0.35 cm of the path (two-point threshold "
            "3.5 cm) and its energy within 0.16 dB of a per-frame render (amplitude JND "
            "1.6 dB), at 8, 48 and 192 kHz alike."
        ),
    )
    gain_update_frames: int | None = Field(
        default=None,
        ge=1,
        le=limits.MAX_GAIN_UPDATE_FRAMES,
        description=(
            "Frames between two gain computations, overriding `gain_update_s` (None: "
            "`gain_update_s` at the sample rate). For studies of the update interval."
        ),
    )
    gain_ramp: bool = Field(
        default=True,
        description=(
            "Ramp gains linearly between updates (False: hold each update). Held gains "
            "step at every update (zipper noise) and miss the path by up to the distance "
            "travelled between two updates."
        ),
    )
    calibration: Calibration = Field(default_factory=Calibration)
    safety: SafetyLimits = Field(default_factory=SafetyLimits)

    @property
    def gain_step_frames(self) -> int:
        """Frames between two gain computations at this profile's sample rate."""
        if self.gain_update_frames is not None:
            return self.gain_update_frames
        return max(1, round(self.gain_update_s * self.sample_rate_hz))

    def at_block(self, block_frames: int) -> DeviceProfile:
        """This profile with ``block_frames`` changed (the sound card's period), the same
        profile when it is already that.

        Raises
        ------
        ParameterError
            ``block_frames`` is not an integer in [MIN_BLOCK_FRAMES, MAX_BLOCK_FRAMES].
        """
        if block_frames == self.block_frames and not isinstance(block_frames, bool):
            return self
        valid = isinstance(block_frames, int) and not isinstance(block_frames, bool)
        if not valid or not limits.MIN_BLOCK_FRAMES <= block_frames <= limits.MAX_BLOCK_FRAMES:
            raise ParameterError(
                f"block_frames={block_frames!r} must be an integer in "
                f"[{limits.MIN_BLOCK_FRAMES}, {limits.MAX_BLOCK_FRAMES}]"
            )
        return self.model_copy(update={"block_frames": block_frames})

    @classmethod
    def default(cls) -> DeviceProfile:
        """The paper's 4 x 2 armband at 48 kHz (one shared instance)."""
        return _default_profile()

    @classmethod
    def load(cls, path: str | Path) -> DeviceProfile:
        """Load a profile from a ``.toml`` or ``.json`` file.

        Raises
        ------
        DeviceError
            The file cannot be read or parsed, or its layout is degenerate.
        """
        return read_model_file(
            cls, Path(path), what="device profile", error=DeviceError, json_unless_toml=True
        )

    @property
    def channels(self) -> int:
        """Number of output channels: the highest channel an actuator uses."""
        return max(a.channel for a in self.actuators)

    def positions_cm(self) -> np.ndarray:
        """Actuator positions, shape (actuators, 2), columns x_cm and y_cm, float64."""
        import numpy as np  # here, so the schema alone does not load numpy

        return np.array([(a.x_cm, a.y_cm) for a in self.actuators], dtype=np.float64)

    @model_validator(mode="before")
    @classmethod
    def _paper_triangles_for_paper_layout(cls, data: object) -> object:
        if isinstance(data, dict) and "actuators" not in data and data.get("triangles") is None:
            return {**data, "triangles": _paper_triangles()}
        return data

    @model_validator(mode="after")
    def _check_layout(self) -> Self:
        import numpy as np

        positions = self.positions_cm()
        n = len(positions)
        channels = [a.channel for a in self.actuators]
        if len(set(channels)) != n:
            raise ValueError(f"actuators: channels {channels} must be distinct")
        distance = np.hypot(*(positions[:, None, :] - positions[None, :, :]).transpose(2, 0, 1))
        distance[np.diag_indices(n)] = np.inf
        i, j = np.unravel_index(np.argmin(distance), distance.shape)
        if distance[i, j] < _MIN_ACTUATOR_DISTANCE_CM:
            raise ValueError(
                f"actuators[{i}] at {_point(positions[i])} cm and actuators[{j}] at "
                f"{_point(positions[j])} cm are {distance[i, j]:.3g} cm apart; at least "
                f"{_MIN_ACTUATOR_DISTANCE_CM} cm required (duplicate actuators)"
            )
        centred = positions - positions.mean(axis=0)
        singular = np.linalg.svd(centred, compute_uv=False)
        span_cm = float(singular[0])
        if singular[1] <= 1e-6 * max(span_cm, 1.0):
            raise ValueError(
                f"actuators at {', '.join(_point(p) for p in positions)} cm are collinear: "
                "a 2D layout needs actuators that span an area"
            )
        for t, triangle in enumerate(self.triangles or ()):
            if any(not 0 <= k < n for k in triangle) or len(set(triangle)) != 3:
                raise ValueError(
                    f"triangles[{t}]={triangle} must name 3 distinct actuators in [0, {n - 1}]"
                )
            a, b, c = positions[list(triangle)]
            area = 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
            if area < _MIN_TRIANGLE_AREA_CM2:
                raise ValueError(
                    f"triangles[{t}]={triangle} has area {area:.3g} cm²; at least "
                    f"{_MIN_TRIANGLE_AREA_CM2} cm² required"
                )
        cal = self.calibration
        for name, values in (
            ("channel_level_db", cal.channel_level_db),
            ("fir_taps", cal.fir_taps),
        ):
            if values is not None and len(values) != self.channels:
                raise ValueError(
                    f"calibration.{name} has {len(values)} entries; the profile has "
                    f"{self.channels} channels"
                )
        if self.safety.max_level_db > cal.reference_level_db:
            raise ValueError(
                f"safety.max_level_db={self.safety.max_level_db} must not exceed "
                f"calibration.reference_level_db={cal.reference_level_db} (full scale)"
            )
        return self


@functools.cache
def _default_profile() -> DeviceProfile:
    """Built on first use: validating a layout loads numpy, the schema alone does not."""
    return DeviceProfile()
