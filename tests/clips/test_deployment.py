"""SDK2 deployments: a game's events read from the Developer Portal's JSON.

The deployments are built in the portal's shape (``tests/support/deployments.py``) from
the corpus's real ``.tact`` files and audio frames written there. Expected lengths are
worked out from the JSON alone (an effect's end is ``startTime + offsetTime``, an audio
clip's length its frames times 20 ms); expected places from the band's actuator span, as
the arm map states it.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import pytest

from phantomtouch.clips.deployment import (
    MAX_EVENTS,
    MAX_NAME_CHARS,
    DeploymentError,
    event_score,
    load_deployment,
    parse_deployment,
)
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.clips.tact_score import ScaleOption, frame_score
from phantomtouch.errors import ParameterError
from phantomtouch.schema import DeviceProfile
from phantomtouch.schema.pattern import KeyframePath
from tests.support.deployments import (
    ARM_CLIP,
    BOTH,
    CLIMB,
    RECOIL,
    VEST_CLIP,
    effects_end_ms,
    frame,
    mapping,
)

DEVICE = DeviceProfile.default()
ARM_MAP = ArmMap()


def test_events_by_name_with_both_pattern_kinds_and_their_lengths() -> None:
    deployment = parse_deployment(json.dumps(BOTH))
    assert list(deployment.events) == ["recoil", "climb", "hit"]
    assert deployment.workspace_id == "ws-123"
    assert deployment.name == "A Game"
    assert deployment.version == 7
    recoil, climb, hit = deployment.events.values()
    assert recoil.length_ms == math.ceil(effects_end_ms(RECOIL))
    # the clip's longest device list is 5 frames of 20 ms (its "duration" 4 is not a length)
    assert hit.length_ms == 5 * 20
    assert climb.length_ms == max(math.ceil(effects_end_ms(CLIMB)), 100)
    assert len(climb.patterns) == 2
    assert deployment.event_times() == {
        "recoil": recoil.length_ms,
        "climb": climb.length_ms,
        "hit": 100,
    }
    assert all(isinstance(t, int) for t in deployment.event_times().values())
    assert recoil.event_time_ms == 100  # the portal's own figure, kept beside
    assert hit.category == "Gameplay"


def test_the_modes_inside_say_where_a_tact_pattern_plays_not_its_position_label() -> None:
    deployment = parse_deployment(BOTH)
    recoil = deployment.events["recoil"]  # labelled LeftArm, content on ForearmR only
    assert recoil.positions() == {"ForearmR"}
    assert recoil.has_arm_content
    left_only = ArmMap(arms=["ForearmL"])
    assert event_score(recoil, left_only, DEVICE).voices == ()
    assert event_score(recoil, ArmMap(arms=["ForearmR"]), DEVICE).voices


def test_every_spelling_of_the_document_reads_the_same() -> None:
    text = json.dumps(BOTH)
    lower = json.loads(
        text.replace('"message"', '"Message"').replace('"hapticMappings"', '"HAPTICMAPPINGS"')
    )
    expected = parse_deployment(BOTH).event_times()
    for document in (
        text,
        text.encode("utf-8"),
        "\ufeff" + text,
        json.dumps(text),  # the text sent once more as a JSON string
        BOTH["message"],
        BOTH["message"]["hapticMappings"],
        lower,
    ):
        assert parse_deployment(document).event_times() == expected
    assert parse_deployment(BOTH["message"]["hapticMappings"]).workspace_id is None


def test_an_arm_frame_plays_where_sdk1_dot_mode_plays_the_same_dots() -> None:
    """Audio frames of an arm become phantom levels by the rule of SDK1's dot mode."""
    hit = parse_deployment(BOTH).events["hit"]
    played = event_score(hit, ARM_MAP, DEVICE)
    # SDK1: a frame submit of dot index 2 at 50 (of 100) for 60 ms on ForearmL
    sdk1 = frame_score("ForearmL", [(2, 0.5)], [], 60.0, ARM_MAP, DEVICE)
    assert len(played.voices) == len(sdk1.voices) == 1
    ours, theirs = played.voices[0].pattern, sdk1.voices[0].pattern
    assert isinstance(ours.path, KeyframePath) and isinstance(theirs.path, KeyframePath)
    first, other = ours.path.keyframes[0], theirs.path.keyframes[0]
    assert (first.x_cm, first.y_cm, first.intensity) == (other.x_cm, other.y_cm, other.intensity)
    # and that place is, by the arm map's statement, the band's first actuator column at
    # its far ring: Tactosy index 2 is x = 1 (along the band), y = 0 (around it)
    xs = [a.x_cm for a in DEVICE.actuators]
    ys = [a.y_cm for a in DEVICE.actuators]
    assert (first.x_cm, first.y_cm) == pytest.approx((min(xs), max(ys)))
    assert first.intensity == pytest.approx(0.5)
    assert ours.intensity == pytest.approx(ARM_MAP.max_intensity)
    # it holds for the 3 frames (60 ms) and ends silent
    last = ours.path.keyframes[-1]
    assert last.intensity == 0.0
    assert last.t_s == pytest.approx(0.060)


def test_levels_past_100_are_clamped_and_bytes_past_an_arms_six_motors_ignored() -> None:
    clip = {"patterns": {"ForearmR": [frame(0, 0, 0, 0, 0, 255, 0, 0, 0, 0, 90)]}}
    event = parse_deployment([mapping("loud", clips=[clip])]).events["loud"]
    (content,) = event.patterns[0].effects[0].contents
    assert content.position == "ForearmR"
    assert [(p.index, p.intensity) for p in content.dots[0].points] == [(5, 1.0)]


def test_intensity_and_duration_scale_an_event() -> None:
    half = mapping("hit", clips=[ARM_CLIP], intensity=50)
    event = parse_deployment([half]).events["hit"]
    assert event.intensity == 0.5
    played = event_score(event, ARM_MAP, DEVICE, ScaleOption.of(1.0, 2.0))
    assert played.duration_s == pytest.approx(2 * 0.100)
    path = played.voices[0].pattern.path
    assert isinstance(path, KeyframePath)
    assert path.keyframes[0].intensity == pytest.approx(0.25)  # 50 % of level 50
    assert path.keyframes[-1].t_s == pytest.approx(2 * 0.060)


def test_a_disabled_mapping_is_no_event_and_a_vest_only_one_plays_nothing_here() -> None:
    deployment = parse_deployment(
        [mapping("off", clips=[ARM_CLIP], enable=False), mapping("vest", clips=[VEST_CLIP])]
    )
    assert list(deployment.events) == ["vest"]
    event = deployment.events["vest"]
    assert event.length_ms == 60
    assert event.positions() == {"VestFront"}
    assert not event.has_arm_content
    assert event_score(event, ARM_MAP, DEVICE).voices == ()


def test_a_tact_file_may_come_as_its_json_text() -> None:
    deployment = parse_deployment([mapping("recoil", tact_files=[("Unknown", json.dumps(RECOIL))])])
    assert deployment.events["recoil"].length_ms == math.ceil(effects_end_ms(RECOIL))


def test_load_reads_a_file(tmp_path: Path) -> None:
    path = tmp_path / "default-config.json"
    path.write_text(json.dumps(BOTH), encoding="utf-8")
    assert list(load_deployment(path).events) == ["recoil", "climb", "hit"]
    with pytest.raises(ParameterError, match="cannot read"):
        load_deployment(tmp_path / "missing.json")


def broken(path: list[Any], value: Any) -> dict[str, Any]:
    """``BOTH`` with the field at ``path`` (from ``message``) set to ``value``."""
    document = copy.deepcopy(BOTH)
    node: Any = document["message"]
    for step in path[:-1]:
        node = node[step]
    node[path[-1]] = value
    return document


@pytest.mark.parametrize(
    ("document", "field", "words"),
    [
        ("", "", "empty"),
        ("{not json", "", "not JSON"),
        ("[1, 2", "", "not JSON"),
        ('"just text"', "", "not JSON"),
        (json.dumps(json.dumps("twice")), "", "JSON string"),
        (json.dumps(42), "", "JSON object"),
        ({"status": True}, "hapticMappings", "must be a list"),
        ({"message": "nope"}, "message", "must be an object"),
        (broken(["hapticMappings"], {"a": 1}), "message.hapticMappings", "must be a list"),
        (broken(["hapticMappings", 1], 7), "message.hapticMappings[1]", "must be an object"),
        (broken(["hapticMappings", 0, "key"], None), "message.hapticMappings[0].key", "1-256"),
        (broken(["hapticMappings", 0, "key"], ""), "message.hapticMappings[0].key", "1-256"),
        (
            broken(["hapticMappings", 2, "key"], "x" * (MAX_NAME_CHARS + 1)),
            "message.hapticMappings[2].key",
            "1-256",
        ),
        (
            broken(["hapticMappings", 2, "key"], "recoil"),
            "message.hapticMappings[2].key",
            "repeats",
        ),
        (
            broken(["hapticMappings", 0, "eventTime"], 150.5),
            "message.hapticMappings[0].eventTime",
            r"integer within \[0, 600000\]",
        ),
        (
            broken(["hapticMappings", 0, "eventTime"], -1),
            "message.hapticMappings[0].eventTime",
            "integer within",
        ),
        (
            broken(["hapticMappings", 0, "eventTime"], "soon"),
            "message.hapticMappings[0].eventTime",
            "integer within",
        ),
        (
            broken(["hapticMappings", 1, "intensity"], 150),
            "message.hapticMappings[1].intensity",
            r"within \[0, 100\]",
        ),
        (
            broken(["hapticMappings", 0, "tactFilePatterns"], {"x": 1}),
            "message.hapticMappings[0].tactFilePatterns",
            "must be a list",
        ),
        (
            broken(["hapticMappings", 0, "tactFilePatterns", 0, "tactFile"], 3),
            "message.hapticMappings[0].tactFilePatterns[0].tactFile",
            "project object",
        ),
        (
            broken(
                [
                    "hapticMappings",
                    0,
                    "tactFilePatterns",
                    0,
                    "tactFile",
                    "tracks",
                    0,
                    "effects",
                    0,
                    "startTime",
                ],
                "later",
            ),
            "message.hapticMappings[0].tactFilePatterns[0].tactFile.tracks[0].effects[0].startTime",
            r"tactFile: tracks\[0\]\.effects\[0\]\.startTime='later' must be a number",
        ),
        (
            broken(["hapticMappings", 2, "audioFilePatterns", 0, "clip"], None),
            "message.hapticMappings[2].audioFilePatterns[0].clip",
            "must be an object",
        ),
        (
            broken(["hapticMappings", 2, "audioFilePatterns", 0, "clip", "patterns"], ["AAAA"]),
            "message.hapticMappings[2].audioFilePatterns[0].clip.patterns",
            "must be an object of device -> frames",
        ),
        (
            broken(
                ["hapticMappings", 2, "audioFilePatterns", 0, "clip", "patterns", "ForearmL"],
                [frame(1), "AAEC"],
            ),
            "message.hapticMappings[2].audioFilePatterns[0].clip.patterns.ForearmL[1]",
            "='AAEC' decodes to 3 bytes; a frame has exactly 20",
        ),
        (
            broken(
                ["hapticMappings", 2, "audioFilePatterns", 0, "clip", "patterns", "ForearmL"],
                ["not base64!"],
            ),
            "message.hapticMappings[2].audioFilePatterns[0].clip.patterns.ForearmL[0]",
            "='not base64!' is not base64",
        ),
        (
            broken(
                ["hapticMappings", 2, "audioFilePatterns", 0, "clip", "patterns", "ForearmL"],
                [12],
            ),
            "message.hapticMappings[2].audioFilePatterns[0].clip.patterns.ForearmL[0]",
            "=12 must be a base64 string",
        ),
    ],
)
def test_a_refused_deployment_names_the_field_and_its_value(
    document: Any, field: str, words: str
) -> None:
    with pytest.raises(DeploymentError, match=words) as caught:
        parse_deployment(document)
    assert caught.value.field == field
    assert isinstance(caught.value, ParameterError)
    if field:  # the message names the field (a tact file's inner path after its own)
        assert field.replace(".tactFile.", ".tactFile: ") in str(caught.value)


def test_ten_thousand_events_are_refused_at_once() -> None:
    many = [mapping(f"e{i}") for i in range(10_000)]
    with pytest.raises(DeploymentError, match=f"10000 mappings; at most {MAX_EVENTS}") as caught:
        parse_deployment({"hapticMappings": many})
    assert caught.value.field == "hapticMappings"


def test_a_huge_frame_list_is_refused_with_its_path() -> None:
    clip = {"patterns": {"ForearmL": [frame()] * 30_001}}
    with pytest.raises(DeploymentError, match="30001 frames; at most 30000") as caught:
        parse_deployment([mapping("long", clips=[clip])])
    assert caught.value.field == "[0].audioFilePatterns[0].clip.patterns.ForearmL"


def test_nan_is_refused_wherever_it_is() -> None:
    with pytest.raises(DeploymentError, match="eventTime=nan"):
        parse_deployment(broken(["hapticMappings", 0, "eventTime"], float("nan")))
    text = json.dumps(BOTH).replace('"intensity": 100', '"intensity": NaN', 1)
    with pytest.raises(DeploymentError, match="intensity=nan must be a number within"):
        parse_deployment(text)


def test_a_clip_of_too_many_points_is_refused_naming_the_device() -> None:
    # every motor changes level every frame: each frame is 6 points per arm
    flicker = [frame(*[100 - 50 * (k % 2)] * 6) for k in range(20_000)]
    clip = {"patterns": {"ForearmL": flicker, "ForearmR": flicker}}
    with pytest.raises(DeploymentError, match="past 200000 points") as caught:
        parse_deployment([mapping("huge", clips=[clip])])
    assert caught.value.field == "[0].audioFilePatterns[0].clip.patterns.ForearmR"
    # held levels are one point per run, however long: a 10-minute hold is 12 points
    held = [frame(*[100] * 6)] * 30_000
    event = parse_deployment([mapping("long", clips=[{"patterns": {"ForearmL": held}}])])
    (content,) = event.events["long"].patterns[0].effects[0].contents
    assert [(fb.start_ms, fb.end_ms, len(fb.points)) for fb in content.dots] == [
        (0, 600_000, 1)
    ] * 6


def test_a_device_the_band_does_not_play_is_summed_up_not_kept_frame_by_frame() -> None:
    vest = [frame(), frame(10, 0, 30), frame(40, 20), frame()]
    event = parse_deployment([mapping("v", clips=[{"patterns": {"VestBack": vest}}])])
    (content,) = event.events["v"].patterns[0].effects[0].contents
    (summary,) = content.dots
    assert (content.position, summary.start_ms, summary.end_ms) == ("VestBack", 20, 60)
    assert [(p.index, p.intensity) for p in summary.points] == [(0, 0.4), (1, 0.2), (2, 0.3)]
    assert event.events["v"].length_ms == 80
