"""Apple Core Haptics' ``.ahap`` to a clip.

The file is JSON: ``{"Version": 1.0, "Pattern": [entry, ...]}``, each entry one of

- ``{"Event": {"Time", "EventType", "EventDuration", "EventParameters": [{"ParameterID",
  "ParameterValue"}]}}``: ``HapticTransient`` (a click: ``HapticIntensity``,
  ``HapticSharpness``) or ``HapticContinuous`` (a tone for ``EventDuration`` s, with
  ``AttackTime`` and ``ReleaseTime`` ramps); audio events (``AudioContinuous``,
  ``AudioCustom``) are not played, and a :class:`~phantomtouch.clips.load.ClipWarning`
  names them;
- ``{"Parameter": {"ParameterID", "Time", "ParameterValue"}}``: a dynamic parameter set
  from ``Time`` on;
- ``{"ParameterCurve": {"ParameterID", "Time", "ParameterCurveControlPoints": [{"Time",
  "ParameterValue"}]}}``: a dynamic parameter moving in straight lines between control
  points (their times counted from the curve's).

The clip: amplitude = ``min(1, sum of the continuous events' envelopes)`` times
``HapticIntensityControl`` (default 1); frequency = the intensity-weighted sharpness of
the sounding continuous events plus ``HapticSharpnessControl`` (default 0), within 0-1;
each transient event a transient with its intensity times the intensity control and its
sharpness plus the sharpness control. Attack and release ramps are straight lines here
(Core Haptics shapes them itself); the envelopes are sampled at every corner of the
events and curves and four times between, where two ramps multiply. The document is
checked by :mod:`~phantomtouch.clips.ahap_schema` (plain dicts); the conversion takes
time linear in the file (:mod:`~phantomtouch.clips.ahap_envelope`; benchmarks/bench_clips.py).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from phantomtouch.clips.ahap_envelope import SOUNDING, Control, kept_points, summed_envelope
from phantomtouch.clips.ahap_schema import AhapEvent, AhapFile
from phantomtouch.clips.load import ClipWarning
from phantomtouch.errors import ParameterError
from phantomtouch.schema.clip import MAX_CLIP_POINTS, HapticClip

_SUBDIVISIONS = 4
DIGITS = 12
"""Decimals kept of each envelope value (the audio path is float32, 7 digits)."""
_EMPTY_S = 0.1
"""Length of a clip with nothing but transients at time 0, s."""
_NAMED = 5
"""Most unplayed entries a warning names one by one (it counts the rest)."""


def _warn_unplayed(unplayed: list[str], source: str) -> None:
    """One line naming what of the file is not played, by path."""
    if not unplayed:
        return
    named = ", ".join(unplayed[:_NAMED])
    more = f" and {len(unplayed) - _NAMED} more" if len(unplayed) > _NAMED else ""
    warnings.warn(
        f"{source}: not played (the armband plays haptic events, intensity and sharpness): "
        f"{named}{more}",
        ClipWarning,
        stacklevel=3,
    )


def clip_of_ahap(document: AhapFile, *, source: str = "clip") -> HapticClip:
    """The clip a validated ``.ahap`` document describes, in time linear in its entries.

    Audio events and the dynamic parameters a clip has no place for (audio, attack, decay
    and release controls) are left out and named in one :class:`ClipWarning`.

    Raises
    ------
    ParameterError
        The clip would have more than ``MAX_CLIP_POINTS`` breakpoints in an envelope.
    """
    intensity = Control(1.0)
    sharpness = Control(0.0)
    continuous: list[tuple[float, float, float, float, float, float]] = []
    transients: list[tuple[float, float, float]] = []
    unplayed: list[str] = []
    for index, entry in enumerate(document["Pattern"]):
        event = entry.get("Event")
        if event is not None:
            kind = event["EventType"]
            if kind.startswith("Audio"):
                unplayed.append(f"Pattern[{index}].Event ({kind})")
            elif kind == "HapticContinuous":
                given = _parameters(event)
                continuous.append(
                    (
                        event["Time"],
                        event.get("EventDuration") or 0.0,
                        given.get("AttackTime", 0.0),
                        given.get("ReleaseTime", 0.0),
                        given.get("HapticIntensity", 1.0),
                        given.get("HapticSharpness", 0.5),
                    )
                )
            elif kind == "HapticTransient":
                given = _parameters(event)
                transients.append(
                    (
                        event["Time"],
                        given.get("HapticIntensity", 1.0),
                        given.get("HapticSharpness", 0.5),
                    )
                )
            continue
        # a Parameter is a curve of one point, at its own time
        name = "Parameter" if "Parameter" in entry else "ParameterCurve"
        curve: Any = entry.get(name)
        if curve is None:
            continue
        control = _control(curve["ParameterID"], intensity, sharpness)
        if control is None:
            unplayed.append(f"Pattern[{index}].{name} ({curve['ParameterID']})")
            continue
        points = (
            curve["ParameterCurveControlPoints"]
            if name == "ParameterCurve"
            else [{"Time": 0.0, "ParameterValue": curve["ParameterValue"]}]
        )
        control.add(
            curve["Time"] + np.array([p["Time"] for p in points]),
            np.array([p["ParameterValue"] for p in points]),
        )
    _warn_unplayed(unplayed, source)

    events = np.array(continuous, dtype=np.float64).reshape(-1, 6)
    starts, durations = events[:, 0], events[:, 1]
    ends = starts + durations
    attacks = np.minimum(np.maximum(0.0, events[:, 2]), durations)
    releases = np.minimum(np.maximum(0.0, events[:, 3]), durations - attacks)
    levels = np.clip(events[:, 4], 0.0, 1.0)
    weights = levels * np.clip(events[:, 5], 0.0, 1.0)
    clicks = np.array(transients, dtype=np.float64).reshape(-1, 3)
    clicks = clicks[np.argsort(clicks[:, 0], kind="stable")]
    clicks_s = clicks[:, 0]
    grid = np.unique(
        np.concatenate(
            (
                [0.0],
                intensity.corners(),
                sharpness.corners(),
                starts,
                ends,
                starts + attacks,
                ends - releases,
            )
        )
    )
    end_s = float(max(grid[-1], clicks_s[-1] if len(clicks_s) else 0.0))
    steps = np.arange(_SUBDIVISIONS)
    fine = np.concatenate(
        (
            (grid[:-1, None] + np.diff(grid)[:, None] * steps[None, :] / _SUBDIVISIONS).ravel(),
            grid[-1:],
        )
    )

    sums = summed_envelope(fine, starts, ends, attacks, releases, levels, weights)
    level = _sides(sums[0], sums[1])
    weighted = _sides(sums[2], sums[3])
    sounding = level > SOUNDING
    sharp = np.where(sounding, weighted / np.where(sounding, level, 1.0), np.nan)
    last = np.maximum.accumulate(np.where(np.isnan(sharp), -1, np.arange(len(sharp))))
    last_sharpness = np.where(last >= 0, sharp[np.maximum(last, 0)], 0.5)
    times = np.repeat(fine, 2)
    value_a = np.minimum(1.0, np.where(sounding, level, 0.0)) * np.clip(
        _sides(intensity.at(fine, left=True), intensity.at(fine, left=False)), 0.0, 1.0
    )
    value_f = np.clip(
        last_sharpness + _sides(sharpness.at(fine, left=True), sharpness.at(fine, left=False)),
        0.0,
        1.0,
    )
    # Plain dicts, validated at once by the clip's model (one pass in pydantic-core).
    click_amplitudes = np.clip(clicks[:, 1], 0.0, 1.0) * np.clip(
        intensity.at(clicks_s, left=False), 0.0, 1.0
    )
    click_frequencies = np.clip(clicks[:, 2] + sharpness.at(clicks_s, left=False), 0.0, 1.0)
    click_dicts = [
        {"t_s": t_s, "amplitude": amplitude, "frequency": frequency}
        for t_s, amplitude, frequency in zip(
            clicks_s.tolist(), click_amplitudes.tolist(), click_frequencies.tolist(), strict=True
        )
    ]
    return HapticClip.model_validate(
        {
            "duration_s": end_s if end_s > 0.0 else _EMPTY_S,
            "amplitude": _breakpoints(times, value_a, "amplitude"),
            "frequency": _breakpoints(times, value_f, "frequency"),
            "transients": click_dicts,
        }
    )


def _sides(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Each grid time's two sides in a row: left, right, left, right, ..."""
    return np.stack((left, right), axis=1).ravel()


def _breakpoints(times: np.ndarray, values: np.ndarray, field: str) -> list[dict[str, float]]:
    """The breakpoints that draw ``values``; they are rounded to :data:`DIGITS` decimals
    first, so that sums equal but for rounding form one flat run."""
    values = np.round(values, DIGITS)
    kept = kept_points(times, values)
    if len(kept) > MAX_CLIP_POINTS:
        raise ParameterError(
            f"{field}: the events make {len(kept)} breakpoints; a clip may have "
            f"{MAX_CLIP_POINTS} (max_clip_points)"
        )
    return [
        {"t_s": t_s, "value": value}
        for t_s, value in zip(times[kept].tolist(), values[kept].tolist(), strict=True)
    ]


def _control(parameter: str, intensity: Control, sharpness: Control) -> Control | None:
    if parameter == "HapticIntensityControl":
        return intensity
    if parameter == "HapticSharpnessControl":
        return sharpness
    return None  # the others shape what a clip does not have (audio, ramp times)


def _parameters(event: AhapEvent) -> dict[str, float]:
    """The event's parameters by name; of a name given twice, the first."""
    return {
        p["ParameterID"]: p["ParameterValue"] for p in reversed(event.get("EventParameters", []))
    }
