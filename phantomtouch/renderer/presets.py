"""Named patterns: the paper's stimuli and a few for VR scenes.

- ``exp1/<signal>-<intensity>-v<speed>[-am]``: the 84 stimuli of experiment 1, a stroke
  up the whole band (wrist to elbow) and back down, 1D mode, each direction with its own
  0.6 s fades; signal in sine50|sine100|sine150|combined50|combined100|combined150|noise,
  intensity low|high (Table I), speed 3|10|18 cm/s, ``-am`` for one modulation period per
  stroke direction (m = 1).
- ``exp2/central|right|diagonal|curved``: the four 2D strokes of experiment 2 towards the
  wrist, from y = 12 to y = 2.4 cm, 1.7 s of motion each (plus 0.6 s fades), sine 100 Hz,
  low intensity (128 dB), no modulation.
- ``vr/tap``, ``vr/stroke``, ``vr/caress``: short touches for collisions in a VR scene.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

from phantomtouch.errors import ParameterError
from phantomtouch.schema.pattern import TouchPattern

BAND_LENGTH_CM = 14.4
BAND_WIDTH_CM = 3.8
EXP2_MOTION_S = 1.7
EXP2_START_Y_CM = 12.0
EXP2_END_Y_CM = 2.4

EXP1_SIGNALS: dict[str, dict[str, Any]] = {
    **{f"sine{f}": {"kind": "sine", "freq_hz": float(f)} for f in (50, 100, 150)},
    **{f"combined{f}": {"kind": "combined", "freq_hz": float(f)} for f in (50, 100, 150)},
    "noise": {"kind": "noise"},
}
EXP1_SPEEDS_CM_S = (3, 10, 18)
EXP1_INTENSITIES = ("low", "high")


def _exp1(signal: str, intensity: str, speed_cm_s: int, am: bool) -> TouchPattern:
    middle_x = BAND_WIDTH_CM / 2
    return TouchPattern.model_validate(
        {
            "path": {
                "kind": "polyline",
                "points_cm": [[middle_x, 0.0], [middle_x, BAND_LENGTH_CM]],
            },
            "speed_cm_s": float(speed_cm_s),
            "repeat": 2,
            "alternate": True,
            "carrier": EXP1_SIGNALS[signal],
            "intensity": intensity,
            "modulation": {"index": 1.0, "freq_hz": "stroke"} if am else None,
            "mode": "1d",
        }
    )


def _exp2(path: dict[str, Any]) -> TouchPattern:
    return TouchPattern.model_validate(
        {
            "path": path,
            "duration_s": 0.6 + EXP2_MOTION_S + 0.6,
            "carrier": {"kind": "sine", "freq_hz": 100.0},
            "intensity": "low",
            "mode": "2d",
        }
    )


def _straight(x0: float, x1: float) -> dict[str, Any]:
    return {"kind": "polyline", "points_cm": [[x0, EXP2_START_Y_CM], [x1, EXP2_END_Y_CM]]}


_CURVED = {
    "kind": "arc",
    "start_cm": [BAND_WIDTH_CM, EXP2_START_Y_CM],
    "through_cm": [0.0, (EXP2_START_Y_CM + EXP2_END_Y_CM) / 2],
    "end_cm": [BAND_WIDTH_CM, EXP2_END_Y_CM],
}


def _vr(
    path: dict[str, Any],
    *,
    fades_s: tuple[float, float],
    freq_hz: float,
    intensity: str,
    **timing: float,
) -> Callable[[], TouchPattern]:
    """A VR touch: ``path`` with its ``timing`` (``speed_cm_s`` or ``duration_s``), fade-in
    and fade-out ``fades_s``, a sine carrier at ``freq_hz`` and a Table I ``intensity``."""
    pattern = {
        "path": path,
        **timing,
        "fade_in_s": fades_s[0],
        "fade_out_s": fades_s[1],
        "carrier": {"kind": "sine", "freq_hz": freq_hz},
        "intensity": intensity,
    }
    return lambda: TouchPattern.model_validate(pattern)


_PRESETS: dict[str, Callable[[], TouchPattern]] = {}
for _signal in EXP1_SIGNALS:
    for _intensity in EXP1_INTENSITIES:
        for _speed in EXP1_SPEEDS_CM_S:
            for _am in (False, True):
                _name = f"exp1/{_signal}-{_intensity}-v{_speed}" + ("-am" if _am else "")
                _PRESETS[_name] = functools.partial(_exp1, _signal, _intensity, _speed, _am)
_PRESETS["exp2/central"] = lambda: _exp2(_straight(BAND_WIDTH_CM / 2, BAND_WIDTH_CM / 2))
_PRESETS["exp2/right"] = lambda: _exp2(_straight(0.0, 0.0))
_PRESETS["exp2/diagonal"] = lambda: _exp2(_straight(BAND_WIDTH_CM, 0.0))
_PRESETS["exp2/curved"] = lambda: _exp2(_CURVED)
_PRESETS["vr/tap"] = _vr(
    {"kind": "polyline", "points_cm": [[BAND_WIDTH_CM / 2, 7.2]]},
    duration_s=0.15,
    fades_s=(0.01, 0.08),
    freq_hz=150.0,
    intensity="high",
)
_PRESETS["vr/stroke"] = _vr(
    {"kind": "polyline", "points_cm": [[BAND_WIDTH_CM / 2, 10.0], [BAND_WIDTH_CM / 2, 4.0]]},
    speed_cm_s=10.0,
    fades_s=(0.1, 0.1),
    freq_hz=100.0,
    intensity="low",
)
_PRESETS["vr/caress"] = _vr(
    {"kind": "spline", "points_cm": [[0.8, 13.0], [3.0, 9.5], [0.8, 6.0], [3.0, 2.5]]},
    speed_cm_s=3.0,
    fades_s=(0.3, 0.3),
    freq_hz=100.0,
    intensity="low",
)


def preset_names() -> list[str]:
    """All preset names, in a stable order (exp1, exp2, vr)."""
    return list(_PRESETS)


def preset(name: str) -> TouchPattern:
    """The pattern of a named preset.

    Raises
    ------
    ParameterError
        Unknown name; the message suggests the closest names.
    """
    try:
        return _PRESETS[name]()
    except KeyError:
        import difflib  # only for a name that is wrong

        close = difflib.get_close_matches(name, _PRESETS, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else "; see `phantomtouch presets`"
        raise ParameterError(f"preset={name!r} is not a known preset{hint}") from None
