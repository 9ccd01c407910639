"""Does the phantom travel along the path, evenly, and what does that exactness cost?

Reference strokes are rendered with gains computed every 1, 8, 32, 128 and 512 frames,
ramped linearly between updates or held (``DeviceProfile.gain_update_frames`` and
``gain_ramp``). Each setting is measured two ways:

- **from the gains**: the per-frame gains the renderer multiplies the carrier with
  (:func:`effective_gains`, the renderer's own ``gain_block`` fed a unit carrier) are
  compared with the per-frame gains of ``gain_update_frames = 1``, and their energy
  centroid ``sum g_i^2 p_i / sum g_i^2`` with the intended point (the path position of
  :func:`~phantomtouch.renderer.trajectory.positions_at`, projected onto the layout);
- **through the twin**: the rendered signals drive the actuator model of
  :mod:`~phantomtouch.analysis.twin` and :func:`~phantomtouch.analysis.perception.perceive`
  reads the phantom's position and level from the modelled accelerations; the intended
  position is averaged over the same windows, weighted by the intended energy. This
  error includes what no gain schedule removes (the actuators' group delay, the window),
  visible as the floor of the per-frame setting.

Statistics cover the frames (windows) whose intended energy is within 20 dB of the
pattern's peak, so the silent ends of fades do not count; level variation covers those
within 3 dB of the peak. CPU time is the best of several timed renders of the whole
stroke (``time.process_time``), per second of audio, also given relative to the
per-frame setting measured in the same run.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from phantomtouch.analysis.perception import (
    DEFAULT_HOP_S,
    DEFAULT_WINDOW_S,
    perceive,
    windowed_mean,
)
from phantomtouch.analysis.twin import ArmbandTwin
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.renderer.presets import preset
from phantomtouch.renderer.render import render, render_blocks
from phantomtouch.renderer.trajectory import (
    control_gains,
    envelope_at,
    modulation_at,
    positions_at,
)
from phantomtouch.renderer.voice import gain_block
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

TWO_POINT_THRESHOLD_CM = 3.5
"""Two-point discrimination threshold on the forearm, cm (Weinstein 1968; docs/algorithms.md)."""
GAIN_UPDATE_FRAMES = (1, 8, 32, 128, 512)
_MASK_ENERGY = 0.01
"""Statistics cover frames whose intended energy is at least this fraction of the peak."""
_LEVEL_MASK_ENERGY = 0.5
"""Level variation covers windows whose intended energy is at least this fraction."""


@dataclass(frozen=True)
class Setting:
    """How often gains are computed along a path and whether they are ramped."""

    gain_update_frames: int
    gain_ramp: bool

    @property
    def label(self) -> str:
        if self.gain_update_frames == 1:
            return "1 (per frame)"
        return f"{self.gain_update_frames} {'ramp' if self.gain_ramp else 'hold'}"

    def device(self, base: DeviceProfile) -> DeviceProfile:
        return base.model_copy(
            update={"gain_update_frames": self.gain_update_frames, "gain_ramp": self.gain_ramp}
        )


def default_settings(frames: Sequence[int] = GAIN_UPDATE_FRAMES) -> list[Setting]:
    """Each update interval in ``frames`` ramped and held (1 frame: once, per frame)."""
    settings = []
    for n in sorted(set(frames)):
        settings += [Setting(n, True)] if n == 1 else [Setting(n, True), Setting(n, False)]
    return settings


def reference_strokes() -> dict[str, TouchPattern]:
    """The strokes the study renders.

    - ``exp1-v18``: experiment 1's fastest stroke (1D, up the band and back, 18 cm/s);
    - ``exp2-curved``: experiment 2's curved 2D stroke (an arc across both columns);
    - ``zigzag-v100``: a fast 2D zig-zag across the band at 100 cm/s (a quick VR swipe,
      three times the fastest stroke of the paper's experiments), four strokes alternating;
    - ``stop-and-go``: keyframes that move, stop, move faster, stop and move on.
    """
    zigzag = [[0.4, 13.6], [3.4, 11.2], [0.4, 8.8], [3.4, 6.4], [0.4, 4.0], [3.4, 1.6]]
    stops = [
        (0.0, 0.5, 12.5),
        (0.5, 1.9, 9.0),
        (1.0, 1.9, 9.0),
        (1.3, 3.3, 5.0),
        (1.8, 3.3, 5.0),
        (2.0, 1.9, 2.0),
    ]
    return {
        "exp1-v18": preset("exp1/sine100-low-v18"),
        "exp2-curved": preset("exp2/curved"),
        "zigzag-v100": TouchPattern.model_validate(
            {
                "path": {"kind": "polyline", "points_cm": zigzag},
                "speed_cm_s": 100.0,
                "fade_in_s": 0.1,
                "fade_out_s": 0.1,
                "repeat": 4,
                "alternate": True,
                "carrier": {"kind": "sine", "freq_hz": 100.0},
                "intensity": "low",
            }
        ),
        "stop-and-go": TouchPattern.model_validate(
            {
                "path": {
                    "kind": "keyframes",
                    "keyframes": [{"t_s": t, "x_cm": x, "y_cm": y} for t, x, y in stops],
                },
                "fade_in_s": 0.3,
                "fade_out_s": 0.3,
                "carrier": {"kind": "sine", "freq_hz": 100.0},
                "intensity": "low",
            }
        ),
    }


def effective_gains(resolved: Plan) -> np.ndarray:
    """The per-frame gains the renderer multiplies the carrier with.

    The gain grid of :class:`~phantomtouch.renderer.voice.PatternRenderer` (every
    ``gain_update_frames`` frames from frame 0) through the renderer's own
    :func:`~phantomtouch.renderer.voice.gain_block`, fed a carrier of ones times the
    per-sample amplitude modulation, as the renderer applies it.

    Returns
    -------
    ndarray, shape (frames, channels), float32
    """
    step = resolved.device.gain_step_frames
    ramp = resolved.device.gain_ramp
    frames = resolved.frames
    last = (frames - 1) // step + (1 if ramp and step > 1 else 0)
    grid_frames = np.arange(last + 1, dtype=np.float64) * step
    grid = control_gains(resolved, grid_frames / resolved.sample_rate_hz, modulated=False)
    grid32 = np.ascontiguousarray(grid, dtype=np.float32)
    carrier = np.ones(frames, dtype=np.float32)
    factor = modulation_at(resolved, np.arange(frames) / resolved.sample_rate_hz)
    if factor is not None:
        carrier *= factor.astype(np.float32)
    return gain_block(carrier, grid32, step, 0, ramp=ramp)


def intended_path(resolved: Plan, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the phantom should be, and with which relative amplitude.

    Returns
    -------
    points_cm : ndarray, shape (n, 2)
        The path's position projected onto the layout; in 1D mode the point between
        the two rows, at their mean x (the phantom runs along the middle of the band).
    envelope : ndarray, shape (n,)
        Fades, modulation and keyframe intensity (1 = the pattern's level).
    """
    points, intensity = positions_at(resolved, times_s)
    envelope = envelope_at(resolved, times_s) * intensity
    geometry = resolved.geometry
    positions = geometry.positions_cm
    if resolved.pattern.mode == "1d":
        lower, beta, _ = geometry.row_weights(points[:, 1])
        row_x = np.array([positions[m, 0].mean() for m in geometry.row_members])
        row_y = geometry.row_y_cm
        x = (1.0 - beta) * row_x[lower] + beta * row_x[lower + 1]
        y = (1.0 - beta) * row_y[lower] + beta * row_y[lower + 1]
        return np.stack([x, y], axis=1), envelope
    triangle, weights, _ = geometry.barycentric(points)
    vertices = positions[geometry.triangles[triangle]]  # (n, 3, 2)
    return np.einsum("nk,nkd->nd", weights, vertices), envelope


def gain_centroid(gains: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Energy centroid of per-channel gains, shape (n, 2); NaN where all gains are 0."""
    energy = np.asarray(gains, dtype=np.float64)[:, geometry.columns] ** 2
    total = energy.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(energy @ geometry.positions_cm / total[:, None])


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values.size else 0.0


def _max(values: np.ndarray) -> float:
    return float(np.max(values)) if values.size else 0.0


@dataclass(kw_only=True)
class Errors:
    """How far one setting's render is from the per-frame one. Gain errors as fractions
    of the pattern's amplitude (worst channel per frame), positions in cm, levels in dB;
    ``silent_windows_twin`` counts windows the render left silent where the pattern
    should be felt (they have no position, so the twin errors leave them out). Over
    several strokes every one of them is the worst stroke's."""

    gain_error_max: float
    gain_error_rms: float
    position_error_gains_max_cm: float
    position_error_gains_rms_cm: float
    level_error_gains_max_db: float
    position_error_twin_max_cm: float
    position_error_twin_rms_cm: float
    level_variation_twin_db: float
    silent_windows_twin: int


@dataclass
class Measurement(Errors):
    """One stroke at one setting: its :class:`Errors`, the mean level offset through the
    twin, dB, and CPU in ms per s."""

    stroke: str
    setting: str
    gain_update_frames: int
    gain_ramp: bool
    duration_s: float
    level_offset_twin_db: float
    cpu_ms_per_s: float
    cpu_blocks_ms_per_s: float


def _cpu_seconds(pattern: TouchPattern, device: DeviceProfile, repeats: int) -> tuple[float, float]:
    """Best CPU time of a whole render, and of a render in the engine's block size."""
    whole = blocks = np.inf
    for _ in range(repeats):
        start = time.process_time()
        render(pattern, device)
        whole = min(whole, time.process_time() - start)
        start = time.process_time()
        for _block in render_blocks(pattern, device, block_frames=device.block_frames):
            pass
        blocks = min(blocks, time.process_time() - start)
    return float(whole), float(blocks)


def measure(
    name: str,
    pattern: TouchPattern,
    setting: Setting,
    *,
    base: DeviceProfile,
    reference_gains: np.ndarray,
    repeats: int = 3,
    window_s: float = DEFAULT_WINDOW_S,
    hop_s: float = DEFAULT_HOP_S,
) -> Measurement:
    """Measure one stroke at one setting against the per-frame ``reference_gains``."""
    device = setting.device(base)
    resolved = plan(pattern, device)
    rate = resolved.sample_rate_hz
    times = np.arange(resolved.frames) / rate
    intended, envelope = intended_path(resolved, times)
    energy = envelope**2
    keep = energy >= _MASK_ENERGY * energy.max()

    gains = effective_gains(resolved)
    scale = resolved.amplitude or 1.0
    delta = (gains - reference_gains)[keep].astype(np.float64)
    reference_energy = float(np.sum(reference_gains[keep].astype(np.float64) ** 2))
    gain_error = np.abs(delta).max(axis=1) / scale
    gain_error_rms = float(np.sqrt(np.sum(delta**2) / reference_energy)) if delta.size else 0.0
    centroid = gain_centroid(gains, resolved.geometry)
    sounding = keep & np.all(np.isfinite(centroid), axis=1)
    position_error = np.hypot(*(centroid - intended)[sounding].T)
    strong = energy >= _LEVEL_MASK_ENERGY * energy.max()
    power = np.sum(gains[strong].astype(np.float64) ** 2, axis=1)
    reference_power = np.sum(reference_gains[strong].astype(np.float64) ** 2, axis=1)
    level_error = np.abs(10.0 * np.log10(power / reference_power))

    accelerations = ArmbandTwin(device).process(render(pattern, device))
    percept = perceive(accelerations, device, window_s=window_s, hop_s=hop_s)
    window, hop = percept.window_frames, percept.hop_frames
    window_energy = windowed_mean(energy, window, hop)
    expected = (
        windowed_mean(intended * energy[:, None], window, hop)
        / np.maximum(window_energy, 1e-300)[:, None]
    )
    sounding = np.isfinite(percept.level_db)  # a silent window has no position to compare
    felt = window_energy >= _MASK_ENERGY * window_energy.max()
    silent = int(np.count_nonzero(felt & ~sounding))
    felt &= sounding
    twin_error = np.hypot(*(percept.positions_cm - expected)[felt].T)
    level_felt = (window_energy >= _LEVEL_MASK_ENERGY * window_energy.max()) & sounding
    expected_db = (resolved.level_db or 0.0) + 10.0 * np.log10(window_energy[level_felt])
    level_deviation = percept.level_db[level_felt] - expected_db

    cpu_s, cpu_blocks_s = _cpu_seconds(pattern, device, repeats)
    return Measurement(
        stroke=name,
        setting=setting.label,
        gain_update_frames=setting.gain_update_frames,
        gain_ramp=setting.gain_ramp,
        duration_s=resolved.duration_s,
        gain_error_max=_max(gain_error),
        gain_error_rms=gain_error_rms,
        position_error_gains_max_cm=_max(position_error),
        position_error_gains_rms_cm=_rms(position_error),
        level_error_gains_max_db=_max(level_error),
        position_error_twin_max_cm=_max(twin_error),
        position_error_twin_rms_cm=_rms(twin_error),
        level_variation_twin_db=float(np.ptp(level_deviation)) if level_deviation.size else 0.0,
        level_offset_twin_db=float(np.mean(level_deviation)) if level_deviation.size else 0.0,
        silent_windows_twin=silent,
        cpu_ms_per_s=1000.0 * cpu_s / resolved.duration_s,
        cpu_blocks_ms_per_s=1000.0 * cpu_blocks_s / resolved.duration_s,
    )


@dataclass
class Row(Errors):
    """One setting over all strokes: the worst stroke's :class:`Errors`; CPU is the total
    CPU time over the total audio time (whole renders, and renders in the engine's
    block size), and relative to the per-frame setting's."""

    setting: str
    gain_update_frames: int
    gain_ramp: bool
    cpu_ms_per_s: float
    cpu_blocks_ms_per_s: float
    cpu_relative: float = 1.0
    cpu_blocks_relative: float = 1.0
    meets_criteria: bool = False


@dataclass
class AccuracyReport:
    """The study: one row per setting, the single measurements, the recommendation."""

    rows: list[Row]
    measurements: list[Measurement]
    recommended: str | None
    criteria: dict[str, float]
    strokes: list[str]
    sample_rate_hz: int
    window_s: float
    hop_s: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _row(setting: Setting, measured: list[Measurement]) -> Row:
    worst = {f.name: max(getattr(m, f.name) for m in measured) for f in fields(Errors)}
    seconds = sum(m.duration_s for m in measured)
    return Row(
        setting=setting.label,
        gain_update_frames=setting.gain_update_frames,
        gain_ramp=setting.gain_ramp,
        cpu_ms_per_s=sum(m.cpu_ms_per_s * m.duration_s for m in measured) / seconds,
        cpu_blocks_ms_per_s=sum(m.cpu_blocks_ms_per_s * m.duration_s for m in measured) / seconds,
        **worst,
    )


VIBRATION_JND_DB = 1.6
"""Smallest just-noticeable difference of vibration amplitude reported (Forta, Griffin
and Morioka, JASA 2012: 1.6-4 dB; the paper quotes about 3 dB)."""

CRITERIA = {
    "position_error_max_cm": TWO_POINT_THRESHOLD_CM / 10.0,
    "level_error_max_db": VIBRATION_JND_DB / 10.0,
    "cpu_tie": 0.10,
}
"""What the recommended default must meet (see :func:`recommend`)."""


def meets_criteria(row: Row, floor: Row, criteria: dict[str, float] = CRITERIA) -> bool:
    """Accurate and continuous enough to be the default (see :func:`recommend`)."""
    position = criteria["position_error_max_cm"]
    level = criteria["level_error_max_db"]
    return (
        (row.gain_ramp or row.gain_update_frames == 1)
        and row.position_error_gains_max_cm <= position
        and row.position_error_twin_max_cm - floor.position_error_twin_max_cm <= position
        and row.level_error_gains_max_db <= level
        and row.level_variation_twin_db - floor.level_variation_twin_db <= level
        and row.silent_windows_twin == 0
    )


def recommend(rows: list[Row], criteria: dict[str, float] = CRITERIA) -> str | None:
    """The cheapest setting that is accurate enough, or None if none is.

    Accurate enough: on every stroke the phantom stays within a tenth of the two-point
    threshold (0.35 cm) of the intended point and the summed energy within a tenth of
    the smallest amplitude JND (0.16 dB) of the per-frame render, from the gains and,
    beyond the per-frame setting's own floor, through the twin. Continuous: gains are
    ramped (held gains step at every update, the zipper noise the design rules out).
    Cheapest: lowest CPU time of a whole render, where the gain schedule's own cost
    shows; settings within ``cpu_tie`` (10 %) of it count as equally cheap, and of
    those the one with the fewest frames between updates wins.
    """
    floor = next((r for r in rows if r.gain_update_frames == 1), None)
    if floor is None:
        return None
    for row in rows:
        row.meets_criteria = meets_criteria(row, floor, criteria)
    good = [r for r in rows if r.meets_criteria]
    if not good:
        return None
    cheapest = min(r.cpu_ms_per_s for r in good)
    tied = [r for r in good if r.cpu_ms_per_s <= cheapest * (1.0 + criteria["cpu_tie"])]
    return min(tied, key=lambda r: r.gain_update_frames).setting


def run_accuracy(
    strokes: dict[str, TouchPattern] | None = None,
    settings: list[Setting] | None = None,
    *,
    device: DeviceProfile | None = None,
    repeats: int = 3,
    window_s: float = DEFAULT_WINDOW_S,
    hop_s: float = DEFAULT_HOP_S,
    progress: Callable[[str], object] | None = None,
) -> AccuracyReport:
    """Run the study.

    Parameters
    ----------
    strokes : dict of name -> TouchPattern, or None for :func:`reference_strokes`
    settings : list of Setting, or None for :func:`default_settings`
        The per-frame setting, the reference of every error, is added first if missing.
    device : DeviceProfile or None
        The device whose ``gain_update_frames`` and ``gain_ramp`` are varied.
    repeats : int, >= 1
        Timed renders per stroke and setting; the fastest counts.
    window_s, hop_s : float
        Perception window and hop.
    progress : callable or None
        Called with ``"setting: stroke"`` after each stroke is measured at a setting.
    """
    base = device or DeviceProfile.default()
    strokes = strokes or reference_strokes()
    per_frame = Setting(1, True)
    settings = list(settings or default_settings())
    if not any(s.gain_update_frames == 1 for s in settings):
        settings.insert(0, per_frame)
    references = {
        name: effective_gains(plan(pattern, per_frame.device(base)))
        for name, pattern in strokes.items()
    }
    measurements: list[Measurement] = []
    rows: list[Row] = []
    for setting in settings:
        measured = []
        for name, pattern in strokes.items():
            measured.append(
                measure(
                    name,
                    pattern,
                    setting,
                    base=base,
                    reference_gains=references[name],
                    repeats=max(1, repeats),
                    window_s=window_s,
                    hop_s=hop_s,
                )
            )
            if progress is not None:
                progress(f"{setting.label}: {name}")
        measurements += measured
        rows.append(_row(setting, measured))
    reference = next(r for r in rows if r.gain_update_frames == 1)
    for row in rows:
        row.cpu_relative = row.cpu_ms_per_s / reference.cpu_ms_per_s
        row.cpu_blocks_relative = row.cpu_blocks_ms_per_s / reference.cpu_blocks_ms_per_s
    return AccuracyReport(
        rows=rows,
        measurements=measurements,
        recommended=recommend(rows),
        criteria=dict(CRITERIA),
        strokes=list(strokes),
        sample_rate_hz=base.sample_rate_hz,
        window_s=window_s,
        hop_s=hop_s,
    )
