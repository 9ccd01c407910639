"""``.tact`` projects: every real file of the corpus, and the recipe's rules one by one.

The corpus (``samples/tact/bhaptics-popone-support``, MIT, its licence beside it) holds 200
files of a real game, 44 of them for the arms. Expected timings are worked out here from
the JSON alone, by the rules of docs/bhaptics.md (".tact files"); places by the mapping's
statement (Tactosy ``x`` along the band from its first ring to its last, ``y`` around it
from its first column to its last); what is measured is the rendered WAV's energy.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile

from phantomtouch.cli import main
from phantomtouch.clips.tact import parse_tact, position_name
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.clips.tact_score import ScaleOption, motor_levels, score
from phantomtouch.renderer.score import render_timed
from phantomtouch.schema import DeviceProfile

CORPUS = Path(__file__).parent / "samples" / "tact" / "bhaptics-popone-support"
FILES = sorted(CORPUS.rglob("*.tact"))
DEVICE = DeviceProfile.default()
RATE = DEVICE.sample_rate_hz
WINDOW = RATE // 1000  # 1 ms
ARMS = {"forearml", "forearmr", "left", "right"}
TOLERANCE_S = 0.040
"""How close the sounding span must be to the effects' (the issue's number)."""


def _get(obj: dict[str, Any], name: str, default: Any = None) -> Any:
    return {k.lower(): v for k, v in obj.items()}.get(name.lower(), default)


def expected_span_ms(document: dict[str, Any]) -> tuple[float, float] | None:
    """When the arms sound, from the JSON: the union of every arm feedback's interval."""
    project = _get(document, "project", document)
    spans = []
    for track in _get(project, "tracks", []):
        if _get(track, "enable", True) is False:
            continue
        for effect in _get(track, "effects", []):
            start, length = (
                float(_get(effect, "startTime", 0)),
                float(_get(effect, "offsetTime", 0)),
            )
            for position, mode in _get(effect, "modes", {}).items():
                if position.lower() not in ARMS:
                    continue
                if str(_get(mode, "mode")).upper() == "PATH_MODE":
                    for fb in _get(_get(mode, "pathMode", {}), "feedback", []):
                        points = [
                            p
                            for p in _get(fb, "pointList", [])
                            if float(_get(p, "intensity", 0)) > 0
                        ]
                        if points:
                            times = sorted(float(_get(p, "time", 0)) for p in _get(fb, "pointList"))
                            end = times[-1] if times[-1] > times[0] else times[0] + 20
                            spans.append((start + times[0], start + min(end, length)))
                else:
                    for fb in _get(_get(mode, "dotMode", {}), "feedback", []):
                        if any(
                            float(_get(p, "intensity", 0)) > 0
                            and 0 <= int(_get(p, "index", -1)) < 20
                            for p in _get(fb, "pointList", [])
                        ):
                            a = start + float(_get(fb, "startTime", 0))
                            b = start + min(float(_get(fb, "endTime", 0)), length)
                            if b > a:
                                spans.append((a, b))
    if not spans:
        return None
    return min(a for a, _ in spans), max(b for _, b in spans)


def sounding_span_s(samples: np.ndarray) -> tuple[float, float]:
    """First and last 1 ms window whose energy is above -40 dB of the loudest."""
    windows = len(samples) // WINDOW
    energy = (samples[: windows * WINDOW].astype(np.float64) ** 2).reshape(windows, WINDOW, -1)
    energy = energy.sum(axis=(1, 2))
    on = np.flatnonzero(energy > 1e-4 * energy.max())
    return on[0] / 1000.0, (on[-1] + 1) / 1000.0


def centroid_cm(samples: np.ndarray) -> np.ndarray:
    """The energy-weighted actuator centroid (x_cm, y_cm) of a whole render."""
    energy = (samples.astype(np.float64) ** 2).sum(axis=0)
    positions = np.zeros((len(energy), 2))
    for actuator in DEVICE.actuators:
        positions[actuator.channel - 1] = (actuator.x_cm, actuator.y_cm)
    return np.asarray(energy @ positions / energy.sum())


def render_cli(path: Path, out: Path, *extra: str) -> np.ndarray:
    assert main(["render", str(path), "-o", str(out), *extra]) == 0
    samples, rate = soundfile.read(str(out), dtype="float32")
    assert rate == RATE
    return np.asarray(samples)


def test_the_corpus_is_all_there() -> None:
    assert len(FILES) == 200
    manifest = json.loads((CORPUS / "MANIFEST.json").read_text(encoding="utf-8"))
    assert sum(entry["arm"] for entry in manifest["files"]) == 44
    assert (CORPUS / "license.md").is_file()


@pytest.mark.parametrize("path", FILES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_file_renders_for_as_long_as_its_arm_effects_or_is_refused_in_one_line(
    path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    document = json.loads(path.read_text(encoding="utf-8-sig"))
    span = expected_span_ms(document)
    out = tmp_path / "out.wav"
    if span is None:
        assert main(["render", str(path), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "no arm content" in err and "Traceback" not in err
        assert not out.exists()
        return
    samples = render_cli(path, out)
    assert np.isfinite(samples).all() and np.abs(samples).max() <= DEVICE.safety.ceiling
    first_s, last_s = sounding_span_s(samples)
    assert abs(first_s - span[0] / 1000) <= TOLERANCE_S, (first_s, span)
    assert abs(last_s - span[1] / 1000) <= TOLERANCE_S, (last_s, span)


def tact(
    modes: dict[str, Any], *, start: float = 0, length: float = 400, **track: Any
) -> dict[str, Any]:
    effect = {"startTime": start, "offsetTime": length, "modes": modes}
    return {"project": {"tracks": [{"effects": [effect], **track}], "layout": {}}}


def dots(
    *points: tuple[int, float], start: float = 0, end: float = 300, playback: str = "NONE"
) -> dict[str, Any]:
    feedback = [
        {
            "startTime": start,
            "endTime": end,
            "playbackType": playback,
            "pointList": [{"index": i, "intensity": v} for i, v in points],
        }
    ]
    return {"mode": "DOT_MODE", "dotMode": {"feedback": feedback}, "pathMode": {"feedback": []}}


def path(*keys: tuple[float, float, float, float]) -> dict[str, Any]:
    points = [{"time": t, "x": x, "y": y, "intensity": v} for t, x, y, v in keys]
    return {
        "mode": "PATH_MODE",
        "dotMode": {"feedback": []},
        "pathMode": {"feedback": [{"playbackType": "NONE", "pointList": points}]},
    }


def rendered(
    document: dict[str, Any] | str | bytes,
    scale: ScaleOption | None = None,
    arm_map: ArmMap | None = None,
) -> np.ndarray:
    played = score(
        parse_tact(document if not isinstance(document, dict) else json.dumps(document)),
        arm_map or ArmMap(),
        DEVICE,
        scale,
    )
    return render_timed(played.voices, DEVICE, duration_s=played.duration_s)


def test_dot_index_2_is_felt_at_the_far_end_on_the_first_column() -> None:
    for arm in ("ForearmL", "ForearmR"):
        where = centroid_cm(rendered(tact({arm: dots((2, 1.0))})))
        # x (1) along the band to its last ring, y (0) on its first column.
        assert np.hypot(*(where - (0.0, 14.4))) < 0.5, (arm, where)


@pytest.mark.parametrize(("x", "y"), [(0.25, 0.5), (0.75, 0.2), (0.5, 0.9), (0.1, 0.1)])
def test_a_path_point_is_a_phantom_at_exactly_its_place_scaled_onto_the_band(
    x: float, y: float
) -> None:
    samples = rendered(tact({"ForearmR": path((0, x, y, 1.0), (300, x, y, 1.0))}))
    expected = (y * 3.8, x * 14.4)
    assert np.hypot(*(centroid_cm(samples) - expected)) < 0.5, (centroid_cm(samples), expected)


def test_a_moving_path_point_moves_linearly_in_time() -> None:
    samples = rendered(tact({"ForearmL": path((0, 0.0, 0.5, 1.0), (400, 1.0, 0.5, 1.0))}))
    for t_ms in (50, 150, 250, 350):
        window = samples[(t_ms - 10) * WINDOW : (t_ms + 10) * WINDOW]
        assert abs(centroid_cm(window)[1] - 14.4 * t_ms / 400) < 0.5, t_ms


def test_each_spelling_in_use_reads_the_same() -> None:
    camel = tact({"ForearmL": dots((1, 0.8), (5, 0.4), start=40, end=200, playback="FADE_OUT")})
    text = json.dumps(camel)
    pascal = text
    for key in (
        "project",
        "tracks",
        "effects",
        "startTime",
        "offsetTime",
        "modes",
        "mode",
        "dotMode",
        "pathMode",
        "feedback",
        "endTime",
        "playbackType",
        "pointList",
        "index",
        "intensity",
    ):
        pascal = pascal.replace(f'"{key}"', f'"{key[0].upper()}{key[1:]}"')
    stringy = (
        json.dumps(json.loads(text), default=str)
        .replace(": 0.8", ': "0.800"')
        .replace(": 200", ': "200"')
    )
    reference = rendered(camel)
    assert np.abs(reference).max() > 0
    for variant in (pascal, stringy, b"\xef\xbb\xbf" + text.encode(), json.loads(text)["project"]):
        document = json.dumps(variant) if isinstance(variant, dict) else variant
        assert np.array_equal(rendered(document), reference)
    legacy = text.replace('"ForearmL"', '"Left"')
    assert np.array_equal(rendered(legacy), reference)
    assert position_name(10) == position_name("forearml") == position_name("Left") == "ForearmL"
    assert position_name("11") == position_name(2) == "ForearmR"
    assert position_name(201) == "VestFront" and position_name("nowhere") is None


def test_missing_arrays_are_nothing_and_bad_numbers_are_refused_naming_the_field() -> None:
    assert score(parse_tact('{"project": {}}'), ArmMap(), DEVICE).voices == ()
    assert (
        score(
            parse_tact(
                json.dumps(
                    {
                        "project": {
                            "tracks": [{"effects": [{"modes": {"ForearmL": {"mode": "DOT_MODE"}}}]}]
                        }
                    }
                )
            ),
            ArmMap(),
            DEVICE,
        ).voices
        == ()
    )
    from phantomtouch.errors import ParameterError

    with pytest.raises(
        ParameterError, match=r"tracks\[0\]\.effects\[0\]\.startTime='soon' must be a number"
    ):
        parse_tact('{"project": {"tracks": [{"effects": [{"startTime": "soon"}]}]}}')
    with pytest.raises(ParameterError, match="not JSON"):
        parse_tact(b"\x00not json")


def test_only_the_sub_object_mode_names_plays() -> None:
    both = dots((0, 1.0))
    both["pathMode"] = path((0, 1.0, 1.0, 1.0), (300, 1.0, 1.0, 1.0))["pathMode"]
    assert np.hypot(*(centroid_cm(rendered(tact({"ForearmL": both}))) - (0.0, 0.0))) < 0.5
    both["mode"] = "PATH_MODE"
    assert np.hypot(*(centroid_cm(rendered(tact({"ForearmL": both}))) - (3.8, 14.4))) < 0.5


def test_an_effect_lasts_offset_time_from_its_start_time() -> None:
    samples = rendered(tact({"ForearmL": dots((0, 1.0), end=500)}, start=300, length=200))
    first_s, last_s = sounding_span_s(samples)
    assert abs(first_s - 0.300) < 0.005 and abs(last_s - 0.500) < 0.005, (first_s, last_s)


def test_dot_feedback_plays_by_its_own_start_and_end() -> None:
    samples = rendered(tact({"ForearmL": dots((0, 1.0), start=100, end=250)}, start=50))
    first_s, last_s = sounding_span_s(samples)
    assert abs(first_s - 0.150) < 0.005 and abs(last_s - 0.300) < 0.005, (first_s, last_s)


def level_at(samples: np.ndarray, t_ms: float) -> float:
    window = samples[int(t_ms - 2) * WINDOW : int(t_ms + 2) * WINDOW].astype(np.float64)
    return float(np.sqrt((window**2).sum(axis=1).mean()))


@pytest.mark.parametrize(
    ("playback", "shape"),
    [
        ("NONE", lambda r: 1.0),
        ("FADE_IN", lambda r: r),
        ("FADE_OUT", lambda r: 1 - r),
        ("FADE_IN_OUT", lambda r: 1 - abs(2 * r - 1)),
    ],
)
def test_playback_type_is_a_linear_envelope(playback: str, shape: Any) -> None:
    samples = rendered(tact({"ForearmL": dots((0, 1.0), end=400, playback=playback)}, length=400))
    full = level_at(rendered(tact({"ForearmL": dots((0, 1.0), end=400)}, length=400)), 200)
    for r in (0.1, 0.3, 0.6, 0.9):
        assert abs(level_at(samples, 400 * r) / full - shape(r)) < 0.03, (playback, r)


def test_a_disabled_track_is_skipped_and_other_positions_play_nothing() -> None:
    assert (
        score(
            parse_tact(json.dumps(tact({"ForearmL": dots((0, 1.0))}, enable=False))),
            ArmMap(),
            DEVICE,
        ).voices
        == ()
    )
    assert (
        score(
            parse_tact(json.dumps(tact({"VestFront": dots((0, 1.0)), "Head": dots((2, 1.0))}))),
            ArmMap(),
            DEVICE,
        ).voices
        == ()
    )


def test_one_arm_only_leaves_the_other_silent() -> None:
    left_only = ArmMap(arms=["ForearmL"])
    assert (
        score(parse_tact(json.dumps(tact({"ForearmR": dots((0, 1.0))}))), left_only, DEVICE).voices
        == ()
    )
    assert score(
        parse_tact(json.dumps(tact({"ForearmL": dots((0, 1.0))}))), left_only, DEVICE
    ).voices


def test_scale_option_stretches_time_and_scales_intensity(tmp_path: Path) -> None:
    stab = CORPUS / "Arm" / "MeleeSlice_L.tact"
    plain = render_cli(stab, tmp_path / "a.wav")
    slow = render_cli(stab, tmp_path / "b.wav", "--scale-duration", "2", "--scale-intensity", "0.5")
    (a0, a1), (b0, b1) = sounding_span_s(plain), sounding_span_s(slow)
    assert abs((b1 - b0) - 2 * (a1 - a0)) <= TOLERANCE_S and abs(b0 - 2 * a0) <= TOLERANCE_S
    assert len(slow) == pytest.approx(2 * len(plain), abs=2)
    ratio = np.sqrt((slow.astype(np.float64) ** 2).sum() / 2) / np.sqrt(
        (plain.astype(np.float64) ** 2).sum()
    )
    assert ratio == pytest.approx(0.5, rel=0.02)


def test_the_arm_map_file_moves_the_points(tmp_path: Path) -> None:
    swapped = tmp_path / "arm.toml"
    swapped.write_text(
        'arms = ["ForearmL"]\n[ForearmL]\norigin_cm = [3.8, 14.4]\nx_end_cm = [3.8, 0.0]\n'
        "y_end_cm = [0.0, 14.4]\n",
        encoding="utf-8",
    )
    doc = tmp_path / "dot.tact"
    doc.write_text(json.dumps(tact({"ForearmL": dots((2, 1.0))})), encoding="utf-8")
    samples = render_cli(doc, tmp_path / "o.wav", "--bhaptics-map", str(swapped))
    assert np.hypot(*(centroid_cm(samples) - (3.8, 0.0))) < 0.5
    bad = tmp_path / "bad.toml"
    bad.write_text("max_intensity = 7\n", encoding="utf-8")
    assert (
        main(["render", str(doc), "-o", str(tmp_path / "x.wav"), "--bhaptics-map", str(bad)]) == 2
    )


def test_motor_levels_light_the_motors_a_dot_and_a_path_point_sit_on() -> None:
    project = parse_tact(
        json.dumps(
            tact(
                {
                    "ForearmL": dots((2, 0.5), end=200),
                    "ForearmR": path((0, 0.5, 1.0, 1.0), (200, 0.5, 1.0, 1.0)),
                }
            )
        )
    )
    levels = motor_levels(project, 100.0)
    assert levels["ForearmL"] == [0, 0, 50, 0, 0, 0]
    assert levels["ForearmR"] == [0, 0, 0, 0, 100, 0]
    assert motor_levels(project, 300.0, ScaleOption(duration=2.0))["ForearmL"][2] == 50
    assert motor_levels(project, 300.0) == {"ForearmL": [0] * 6, "ForearmR": [0] * 6}
