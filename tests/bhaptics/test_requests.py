"""Reading what bHaptics clients send (:mod:`phantomtouch.bhaptics.requests`), each spelling
in use, and the status they read back (:mod:`phantomtouch.bhaptics.status`)."""

from __future__ import annotations

import json

import pytest

import phantomtouch.bhaptics.requests as requests_module
from phantomtouch.bhaptics.requests import (
    BadRequest,
    PlayFrame,
    PlayKey,
    Register,
    TurnOff,
    TurnOffAll,
    parse,
)
from phantomtouch.bhaptics.status import MOTORS, status_message
from phantomtouch.errors import ParameterError


def test_the_cpp_spelling_integer_position_and_both_arrays() -> None:
    message = parse(
        json.dumps(
            {
                "Register": [{"Key": "k", "Project": {"Tracks": []}}],
                "Submit": [
                    {
                        "Type": "frame",
                        "Key": "dot",
                        "Frame": {
                            "DurationMillis": 200,
                            "Position": 11,
                            "Texture": 0,
                            "DotPoints": [{"Index": 2, "Intensity": 100}],
                            "PathPoints": [],
                        },
                    }
                ],
            }
        )
    )
    register, play = message.requests
    assert register == Register("k", {"Tracks": []})
    assert isinstance(play, PlayFrame)
    assert play.frame.position == "ForearmR" and not play.frame.legacy
    assert play.frame.dots[0].index == 2 and play.frame.dots[0].intensity == 1.0
    assert play.frame.duration_ms == 200


def test_lowercase_strings_for_numbers_a_bom_and_missing_arrays() -> None:
    text = "\ufeff" + json.dumps(
        {
            "submit": [
                {
                    "type": "FRAME",
                    "key": "p",
                    "frame": {
                        "position": "forearml",
                        "pathpoints": [{"x": "1.5", "y": "-1", "intensity": "1e9"}],
                        "durationMillis": "5",
                    },
                }
            ]
        }
    )
    (play,) = parse(text).requests
    assert isinstance(play, PlayFrame)
    point = play.frame.paths[0]
    assert (point.x, point.y, point.intensity, point.motor_count) == (1.0, 0.0, 1.0, 3)
    assert play.frame.dots == () and play.frame.duration_ms == 20


def test_legacy_arms_keep_their_layout() -> None:
    for position in ("Left", 1, "1"):
        submit = {"Type": "frame", "Frame": {"Position": position, "DotPoints": []}}
        (play,) = parse(json.dumps({"Submit": [submit]})).requests
        assert isinstance(play, PlayFrame)
        assert play.frame.position == "ForearmL" and play.frame.legacy and play.frame.empty


def test_key_parameters_and_historical_names() -> None:
    submits = [
        {
            "type": "key",
            "key": "a",
            "Parameters": {
                "altKey": "a#2",
                "scaleOption": {"intensity": "0.5", "duration": 2},
                "startTimeMillis": 40,
            },
        },
        {"Type": "key", "Key": "b", "Parameters": {"intensityRatio": 3, "durationRatio": 0.5}},
        {"Type": "turnOff", "Key": "a#2"},
        {"Type": "turnOffAll"},
    ]
    a, b, off, everything = parse(json.dumps({"Submit": submits})).requests
    assert a == PlayKey("a", "a#2", 0.5, 2.0, 40) and a.name == "a#2"
    assert b == PlayKey("b", None, 3.0, 0.5, 0) and b.name == "b"
    assert off == TurnOff("a#2") and everything == TurnOffAll()


def test_a_bad_request_is_skipped_and_named_the_others_kept() -> None:
    message = parse(
        json.dumps(
            {
                "Submit": [
                    {"Type": "explode"},
                    {"Type": "frame", "Frame": {"Position": "Elbow"}},
                    {"Type": "frame", "Frame": {"Position": 10, "DotPoints": [{"Index": None}]}},
                    {"Type": "turnOffAll"},
                ]
            }
        )
    )
    assert message.requests == (TurnOffAll(),)
    reasons = " ".join(str(s) for s in message.skipped)
    assert "Submit[0]" in reasons and "type='explode'" in reasons
    assert "position='Elbow'" in reasons and "dotPoints.index=None" in reasons


@pytest.mark.parametrize("text", ["not json", "[1]", '{"Submit": 5}', "{" * 100_000])
def test_unreadable_messages_raise_bad_request(text: str) -> None:
    with pytest.raises(BadRequest):
        parse(text)


def test_the_status_always_has_every_key_and_integer_levels() -> None:
    status = status_message(
        registered={"b", "a"},
        active=["a"],
        positions=["ForearmL", "ForearmR"],
        levels={"ForearmL": [100.4, 250, -3], "Head": [1.6] * 9},
    )
    assert status["RegisteredKeys"] == ["a", "b"] and status["ConnectedDeviceCount"] == 2
    levels = status["Status"]
    assert isinstance(levels, dict)
    assert {k: len(v) for k, v in levels.items()} == MOTORS
    assert levels["ForearmL"] == [100, 100, 0, 0, 0, 0]
    assert levels["Head"] == [2] * 6


def test_a_message_over_the_submit_check_is_refused_before_any_request_is_read(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``check_submits`` (the admission's ``check_work``) hears how many items ``Submit``
    holds, an unreadable one too, before any is read; when it refuses, parse raises its
    error and has read none."""
    read: list[object] = []
    monkeypatch.setattr(requests_module, "_submit", lambda item: read.append(item))
    heard: list[int] = []

    def refuse(count: int) -> None:
        heard.append(count)
        raise ParameterError(f"Submit: {count} in one message; at most 64")

    submits = [{"Type": "turnOffAll"}] * 70 + [{"Type": 3}]
    text = json.dumps({"Register": [], "submit": submits})
    with pytest.raises(ParameterError, match="Submit: 71"):
        parse(text, refuse)
    assert heard == [71]
    assert read == []


def test_a_message_the_submit_check_lets_through_reads_as_without_it() -> None:
    heard: list[int] = []
    text = json.dumps(
        {"Submit": [{"Type": "turnOff", "Key": "a"}, {"Type": "turnOffAll"}, {"Type": 3}]}
    )
    checked, unchecked = parse(text, heard.append), parse(text)
    assert heard == [3]
    assert checked.requests == unchecked.requests == (TurnOff("a"), TurnOffAll())
    assert [str(e) for e in checked.skipped] == [str(e) for e in unchecked.skipped]
    assert len(checked.skipped) == 1
