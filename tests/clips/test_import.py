"""``.haptic`` and ``.ahap`` files to clips: the samples, analytic envelopes, refusals."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from phantomtouch.cli import main
from phantomtouch.clips import load_clip, parse_clip
from phantomtouch.errors import ParameterError
from phantomtouch.schema import HapticClip
from phantomtouch.service.store import PatternStore

SAMPLES = Path(__file__).parent / "samples"


def envelope(points: list[Any], times_s: np.ndarray) -> np.ndarray:
    return np.interp(times_s, [p.t_s for p in points], [p.value for p in points])


def test_a_haptic_file_keeps_its_breakpoints_and_its_emphasis() -> None:
    document = json.loads((SAMPLES / "swell.haptic").read_text())
    envelopes = document["signals"]["continuous"]["envelopes"]
    clip = load_clip(SAMPLES / "swell.haptic")
    assert [(p.t_s, p.value) for p in clip.amplitude] == [
        (p["time"], p["amplitude"]) for p in envelopes["amplitude"]
    ]
    assert [(p.t_s, p.value) for p in clip.frequency] == [
        (p["time"], p["frequency"]) for p in envelopes["frequency"]
    ]
    assert [(t.t_s, t.amplitude, t.frequency) for t in clip.transients] == [(1.0, 1.0, 0.8)]
    assert clip.duration_s == 2.4


def test_an_ahap_file_becomes_its_envelope_and_its_transients() -> None:
    clip = load_clip(SAMPLES / "knock.ahap")
    assert [(t.t_s, t.amplitude, t.frequency) for t in clip.transients] == [
        (0.0, 1.0, 0.0),
        (0.3, 0.5, 0.5),
        (0.6, 0.8, 1.0),
    ]
    assert clip.duration_s == pytest.approx(2.5)
    # The continuous event by hand: 0.8 from 1.0 s to 2.5 s, a 0.2 s attack and a 0.3 s
    # release, times the intensity control: 1 until 1.5 s, then down to 0.5 at 2.0 s.
    t = np.linspace(0.0, 2.5, 2501)
    ramp = np.clip((t - 1.0) / 0.2, 0.0, 1.0) * np.clip((2.5 - t) / 0.3, 0.0, 1.0)
    control = np.interp(t, [1.5, 2.0], [1.0, 0.5])
    np.testing.assert_allclose(envelope(clip.amplitude, t), 0.8 * ramp * control, atol=1e-12)
    # Sharpness 0.5, plus the sharpness control's 0.25 from 2.0 s on.
    sounding = (t > 1.0) & (t < 2.5)
    expected = np.where(t < 2.0, 0.5, 0.75)
    np.testing.assert_allclose(envelope(clip.frequency, t)[sounding], expected[sounding])


def _haptic() -> dict[str, Any]:
    return json.loads((SAMPLES / "swell.haptic").read_text())


def _ahap() -> dict[str, Any]:
    return json.loads((SAMPLES / "knock.ahap").read_text())


def _without(document: dict[str, Any], *keys: str | int) -> dict[str, Any]:
    changed = copy.deepcopy(document)
    target = changed
    for key in keys[:-1]:
        target = target[key]
    del target[keys[-1]]
    return changed


def _setting(document: dict[str, Any], value: Any, *keys: str | int) -> dict[str, Any]:
    changed = copy.deepcopy(document)
    target = changed
    for key in keys[:-1]:
        target = target[key]
    target[keys[-1]] = value
    return changed


AMPLITUDE = ("signals", "continuous", "envelopes", "amplitude")
MALFORMED = [
    (".haptic", _without(_haptic(), "signals", "continuous"), "signals.continuous"),
    (".haptic", _setting(_haptic(), [], *AMPLITUDE), "signals.continuous.envelopes.amplitude"),
    (
        ".haptic",
        _setting(_haptic(), 1.5, *AMPLITUDE, 2, "amplitude"),
        "signals.continuous.envelopes.amplitude[2].amplitude=1.5",
    ),
    (
        ".haptic",
        _setting(_haptic(), "soon", *AMPLITUDE, 1, "time"),
        "signals.continuous.envelopes.amplitude[1].time='soon'",
    ),
    (".haptic", _setting(_haptic(), 0.1, *AMPLITUDE, 3, "time"), "amplitude[3].time=0.1"),
    (
        ".haptic",
        _setting(_haptic(), {"amplitude": 2}, *AMPLITUDE, 2, "emphasis"),
        "amplitude[2].emphasis",
    ),
    (".ahap", _without(_ahap(), "Pattern"), "Pattern"),
    (".ahap", _setting(_ahap(), "HapticBuzz", "Pattern", 1, "Event", "EventType"), "EventType"),
    (".ahap", _without(_ahap(), "Pattern", 3, "Event", "EventDuration"), "EventDuration"),
    (
        ".ahap",
        _setting(_ahap(), -0.5, "Pattern", 0, "Event", "Time"),
        "Pattern[0].Event.Time=-0.5",
    ),
    (
        ".ahap",
        _setting(_ahap(), "Loudness", "Pattern", 0, "Event", "EventParameters", 0, "ParameterID"),
        "Pattern[0].Event.EventParameters[0].ParameterID='Loudness'",
    ),
    (
        ".ahap",
        _setting(_ahap(), {"Time": 0.0}, "Pattern", 2),
        "Pattern[2]",
    ),
]


@pytest.mark.parametrize(("suffix", "document", "named"), MALFORMED)
def test_a_malformed_file_is_refused_naming_the_field(
    suffix: str, document: dict[str, Any], named: str
) -> None:
    with pytest.raises(ParameterError) as refused:
        parse_clip(json.dumps(document), suffix=suffix, source=f"bad{suffix}")
    assert named in str(refused.value)
    assert f"bad{suffix}" in str(refused.value)


def test_what_is_not_a_clip_is_refused() -> None:
    with pytest.raises(ParameterError, match="not JSON"):
        parse_clip("{signals", suffix=".haptic")
    with pytest.raises(ParameterError, match=r"'signals'.*'Pattern'"):
        parse_clip('{"tracks": []}')
    # Without a suffix the content tells the format.
    assert parse_clip((SAMPLES / "knock.ahap").read_text()).transients


def test_the_import_command_stores_the_clip_in_the_library(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "library.db"
    assert main(["import", str(SAMPLES / "knock.ahap"), "--db", str(db)]) == 0
    assert "clip 'knock'" in capsys.readouterr().out
    store = PatternStore.open(db)
    try:
        assert store.get_clip("knock") == load_clip(SAMPLES / "knock.ahap")
    finally:
        store.close()
    out = tmp_path / "swell.json"
    assert main(["import", str(SAMPLES / "swell.haptic"), "-o", str(out)]) == 0
    assert HapticClip.model_validate_json(out.read_text()) == load_clip(SAMPLES / "swell.haptic")
    bad = tmp_path / "bad.haptic"
    bad.write_text(json.dumps(MALFORMED[2][1]))
    assert main(["import", str(bad), "--db", str(db)]) == 2
    assert "amplitude[2].amplitude=1.5" in capsys.readouterr().err
