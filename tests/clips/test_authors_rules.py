"""Clip files checked by their authors' rules: Lofelt's data model v1, Apple's ranges.

The ``.haptic`` files in ``samples/lofelt`` are written by hand from Lofelt's data model
v1 as documented (the steps, amplitude-only and empty-frequency clips Studio exports) and
one per refusal of Lofelt's validator (``validate`` of the data model's v1: an empty
amplitude envelope; an amplitude, frequency or emphasis value outside 0-1; times that go
back, counted from 0; an emphasis amplitude below its breakpoint's). ``phantomtouch
import`` must give each the validator's verdict, and name the field when it refuses.
"""

from __future__ import annotations

import copy
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from phantomtouch import TouchPattern, render
from phantomtouch.cli import main
from phantomtouch.clips import ClipWarning, load_clip, parse_clip
from phantomtouch.errors import ParameterError

LOFELT = Path(__file__).parent / "samples" / "lofelt"
KNOCK = Path(__file__).parent / "samples" / "knock.ahap"
ENVELOPES = "signals.continuous.envelopes"

VERDICTS: dict[str, str | None] = {
    # accepted by Lofelt's validator
    "step.haptic": None,
    "amplitude_only.haptic": None,
    "empty_frequency.haptic": None,
    "emphasis_equal.haptic": None,
    # refused by it, and here naming the field
    "refused_empty_amplitude.haptic": f"{ENVELOPES}.amplitude",
    "refused_amplitude_range.haptic": f"{ENVELOPES}.amplitude[1].amplitude=1.2",
    "refused_amplitude_times.haptic": f"{ENVELOPES}.amplitude[2].time=0.3 must not be before",
    "refused_negative_time.haptic": f"{ENVELOPES}.amplitude[0].time=-0.1",
    "refused_emphasis_amplitude_range.haptic": f"{ENVELOPES}.amplitude[0].emphasis.amplitude=1.5",
    "refused_emphasis_frequency_range.haptic": (
        f"{ENVELOPES}.amplitude[0].emphasis.frequency=-0.1"
    ),
    "refused_emphasis_below_envelope.haptic": "emphasis.amplitude=0.5 is below",
    "refused_frequency_range.haptic": f"{ENVELOPES}.frequency[1].frequency=1.1",
    "refused_frequency_times.haptic": f"{ENVELOPES}.frequency[2].time=0.2 must not be before",
}


def test_every_hand_written_file_has_a_verdict() -> None:
    assert sorted(VERDICTS) == sorted(p.name for p in LOFELT.glob("*.haptic"))


@pytest.mark.parametrize(("name", "refusal"), sorted(VERDICTS.items()))
def test_import_agrees_with_lofelts_validator(
    name: str, refusal: str | None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["import", str(LOFELT / name), "-o", str(tmp_path / "clip.json")])
    err = capsys.readouterr().err
    if refusal is None:
        assert code == 0, err
    else:
        assert code == 2 and refusal in err, err


def test_a_step_is_two_breakpoints_at_one_time() -> None:
    clip = load_clip(LOFELT / "step.haptic")
    assert [(p.t_s, p.value) for p in clip.amplitude] == [
        (0.0, 0.2),
        (0.5, 0.2),
        (0.5, 0.9),
        (1.0, 0.9),
    ]
    assert [p.t_s for p in clip.frequency] == [0.0, 0.5, 0.5, 1.0]


@pytest.mark.parametrize("name", ["amplitude_only.haptic", "empty_frequency.haptic"])
def test_without_a_frequency_envelope_the_clip_keeps_the_middle_frequency(name: str) -> None:
    clip = load_clip(LOFELT / name)
    assert [(p.t_s, p.value) for p in clip.frequency] == [(0.0, 0.5)]


@pytest.mark.parametrize("name", ["step.haptic", "amplitude_only.haptic", "empty_frequency.haptic"])
def test_the_clips_studio_exports_render_finite_within_the_ceiling(name: str) -> None:
    clip = load_clip(LOFELT / name)
    pattern = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
            "duration_s": 2.0,
            "carrier": {"kind": "clip", "data": clip.model_dump()},
            "intensity": 1.0,
        }
    )
    out = render(pattern)
    assert np.all(np.isfinite(out)) and 0.0 < np.max(np.abs(out)) <= 1.0


def test_the_amplitude_only_clips_emphasis_is_its_transient() -> None:
    clip = load_clip(LOFELT / "amplitude_only.haptic")
    assert [(t.t_s, t.amplitude, t.frequency) for t in clip.transients] == [(0.1, 1.0, 0.6)]


# --- .ahap: Apple's ranges, and what the engine does not play --------------------------


def _knock() -> dict[str, Any]:
    return json.loads(KNOCK.read_text())


def _set(document: dict[str, Any], value: Any, *keys: str | int) -> str:
    changed = copy.deepcopy(document)
    target: Any = changed
    for key in keys[:-1]:
        target = target[key]
    target[keys[-1]] = value
    return json.dumps(changed)


EVENT0 = ("Pattern", 0, "Event", "EventParameters")
OUT_OF_RANGE = [
    (_set(_knock(), 1.5, *EVENT0, 0, "ParameterValue"), "Pattern[0].Event.EventParameters[0]"),
    (_set(_knock(), -0.1, *EVENT0, 1, "ParameterValue"), "HapticSharpness's range 0 to 1"),
    (
        _set(_knock(), 2.0, "Pattern", 3, "Event", "EventParameters", 2, "ParameterValue"),
        "AttackTime's range 0 to 1",
    ),
    (
        _set(
            _knock(),
            -0.5,
            "Pattern",
            5,
            "ParameterCurve",
            "ParameterCurveControlPoints",
            1,
            "ParameterValue",
        ),
        "Pattern[5].ParameterCurve",
    ),
    (_set(_knock(), 1.5, "Pattern", 6, "Parameter", "ParameterValue"), "Pattern[6].Parameter"),
]


@pytest.mark.parametrize(("text", "named"), OUT_OF_RANGE)
def test_ahap_values_outside_apples_ranges_are_refused_by_path(text: str, named: str) -> None:
    with pytest.raises(ParameterError) as refused:
        parse_clip(text, suffix=".ahap", source="bad.ahap")
    assert named in str(refused.value) and "bad.ahap" in str(refused.value)


def test_audio_events_are_named_in_one_warning_not_dropped_in_silence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    document = _knock()
    document["Pattern"].append(
        {"Event": {"Time": 0.2, "EventType": "AudioCustom", "EventWaveformPath": "knock.wav"}}
    )
    document["Pattern"].append(
        {"Parameter": {"ParameterID": "AudioVolumeControl", "Time": 0.0, "ParameterValue": 0.5}}
    )
    path = tmp_path / "audio.ahap"
    path.write_text(json.dumps(document))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ClipWarning)
        clip = load_clip(path)
    assert len(caught) == 1 and issubclass(caught[0].category, ClipWarning)
    message = str(caught[0].message)
    for part in (
        "audio.ahap",
        "Pattern[4].Event (AudioContinuous)",
        "Pattern[7].Event (AudioCustom)",
        "Pattern[8].Parameter (AudioVolumeControl)",
    ):
        assert part in message, message
    assert clip == load_clip(KNOCK), "the haptic events make the same clip"
    assert main(["import", str(path), "-o", str(tmp_path / "clip.json")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: audio.ahap: not played"), err


def test_a_haptic_only_ahap_warns_of_nothing() -> None:
    document = _knock()
    del document["Pattern"][4]
    with warnings.catch_warnings():
        warnings.simplefilter("error", ClipWarning)
        parse_clip(json.dumps(document), suffix=".ahap")
