"""What an SDK2 client sends, read in every envelope seen on the wire (docs/bhaptics.md,
"SDK2"), and the server's messages as the clients read them."""

from __future__ import annotations

import json
from typing import Any

import pytest

from phantomtouch.bhaptics.requests import BadRequest
from phantomtouch.bhaptics.sdk2.wire import (
    CLIENT_TYPES,
    Auth,
    DeviceRequest,
    PauseRequest,
    PlayEvent,
    PlayPoints,
    StopRequest,
    parse,
    server_message,
)

PLAY = {
    "eventName": "stab",
    "requestId": 43095,
    "intensity": 0.5,
    "duration": 2.0,
    "offsetAngleX": 90.0,
    "offsetY": 0.25,
    "deviceIndex": -1,
}


def spellings(kind: str, message: Any) -> list[str]:
    """The message in each envelope: PascalCase with a string ``Message`` (bHaptics'
    library), lower case (a game's capture), and ``Message`` an object (another SDK)."""
    text = message if isinstance(message, str) else json.dumps(message)
    return [
        json.dumps({"Type": kind, "Message": text}),
        json.dumps({"type": kind, "message": text}),
        json.dumps({"type": kind, "message": message}),
    ]


@pytest.mark.parametrize("text", spellings("SdkPlay", PLAY))
def test_a_play_reads_alike_in_every_envelope(text: str) -> None:
    assert parse(text) == PlayEvent(
        event="stab",
        request_id=43095,
        intensity=0.5,
        duration=2.0,
        offset_angle_x=90.0,
        offset_y=0.25,
    )


def test_play_loop_and_start_time_carry_their_fields() -> None:
    loop = parse(spellings("SdkPlayLoop", {**PLAY, "interval": 200, "maxCount": 3})[0])
    assert isinstance(loop, PlayEvent) and (loop.count, loop.interval_ms) == (3, 200)
    start = parse(spellings("SdkPlayWithStartTime", {**PLAY, "startMillis": 120})[1])
    assert isinstance(start, PlayEvent) and start.start_ms == 120 and start.count == 1


def test_dot_and_path_modes_read_their_points() -> None:
    dots = parse(
        spellings(
            "SdkPlayDotMode",
            {"requestId": 1, "position": 1, "durationMillis": 500, "motorValues": [100, 0, 50]},
        )[0]
    )
    assert dots == PlayPoints(1, "ForearmL", 500, dots=((0, 100.0), (1, 0.0), (2, 50.0)))
    path = parse(
        spellings(
            "SdkPlayPathMode",
            {
                "requestId": 2,
                "position": 2,
                "durationMillis": 300,
                "pathPoints": [{"intensity": 100, "motorCount": 3, "x": 0.5, "y": 0.25}],
            },
        )[1]
    )
    assert path == PlayPoints(2, "ForearmR", 300, paths=((0.5, 0.25, 100.0),))
    vest = parse(
        spellings(
            "SdkPlayDotMode",
            {"requestId": 3, "position": 0, "durationMillis": 100, "motorValues": [100]},
        )[2]
    )
    assert isinstance(vest, PlayPoints) and vest.position is None


def test_stops_pings_and_the_rest_take_a_bare_string() -> None:
    assert parse(spellings("SdkStopByRequestId", "58147")[0]) == StopRequest(request_id=58147)
    assert parse(spellings("SdkStopByEventId", "wobble")[1]) == StopRequest(event="wobble")
    assert parse(spellings("SdkStopAll", "")[0]) == StopRequest()
    assert parse(json.dumps({"Type": "SdkStopAll"})) == StopRequest()
    assert parse(spellings("SdkPing", "pt-l")[0]) == DeviceRequest("SdkPing", "pt-l")
    assert parse(spellings("SdkPingAll", "")[1]) == DeviceRequest("SdkPingAll", "")
    assert parse(spellings("SdkSwapPosition", "pt-l")[0]) == DeviceRequest(
        "SdkSwapPosition", "pt-l"
    )
    vsm = parse(spellings("SdkDeviceSetVSM", {"macAddress": "pt-l", "vsm": 0})[0])
    assert vsm == DeviceRequest("SdkDeviceSetVSM", "pt-l")
    assert parse(spellings("SdkPause", "stab")[0]) == PauseRequest(resume=False, event="stab")
    assert parse(spellings("SdkResume", "")[1]) == PauseRequest(resume=True, event=None)


def test_auth_messages_carry_the_deployment_as_given() -> None:
    auth = {"ApplicationId": "app", "SDKApiKey": "key"}
    assert parse(spellings("SdkRequestAuth", auth)[0]) == Auth("SdkRequestAuth", None)
    reinit = {"sdkApiKey": "key", "workspaceId": "app", "haptic": ""}
    assert parse(spellings("SdkRequestReInit", reinit)[0]) == Auth("SdkRequestReInit", "")
    haptic = json.dumps({"status": True, "message": {"hapticMappings": []}})
    init = {"authentication": json.dumps(auth), "haptic": haptic}
    for text in spellings("SdkRequestAuthInit", init):
        assert parse(text) == Auth("SdkRequestAuthInit", haptic)


def test_every_client_type_is_read() -> None:
    bodies: dict[str, Any] = {
        "SdkPlay": PLAY,
        "SdkPlayWithStartTime": PLAY,
        "SdkPlayLoop": PLAY,
        "SdkPlayDotMode": {"requestId": 1, "position": 1, "durationMillis": 20, "motorValues": []},
        "SdkPlayPathMode": {"requestId": 1, "position": 1, "durationMillis": 20, "pathPoints": []},
        "SdkStopByRequestId": "1",
        "SdkStopByEventId": "x",
    }
    for kind in CLIENT_TYPES:
        assert parse(spellings(kind, bodies.get(kind, ""))[0]) is not None


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("not json", "not JSON"),
        ("[1, 2]", "JSON object"),
        (json.dumps({"Type": "SdkExplode", "Message": ""}), "Type='SdkExplode'"),
        (json.dumps({"Message": ""}), "Type=None"),
        (json.dumps({"Type": "SdkPlay", "Message": [1]}), "Message=[1]"),
        (json.dumps({"Type": "SdkPlay", "Message": "{broken"}), "does not read"),
        (json.dumps({"Type": "SdkPlay", "Message": "stab"}), "must be a JSON object"),
        (spellings("SdkPlay", {**PLAY, "eventName": 5})[0], "eventName=5"),
        (spellings("SdkPlay", {**PLAY, "requestId": "x"})[0], "requestId='x'"),
        (spellings("SdkPlay", {**PLAY, "requestId": -1})[0], "requestId=-1"),
        (
            '{"Type": "SdkPlay", "Message": {"eventName": "s", "requestId": 1, "intensity": NaN}}',
            "intensity=nan must be finite",
        ),
        (
            spellings(
                "SdkPlayDotMode",
                {"requestId": 1, "position": "ForearmL", "durationMillis": 20, "motorValues": []},
            )[0],
            "position='ForearmL'",
        ),
        (
            spellings(
                "SdkPlayDotMode",
                {"requestId": 1, "position": 1, "durationMillis": 20, "motorValues": 7},
            )[0],
            "motorValues=7",
        ),
        (
            spellings(
                "SdkPlayPathMode",
                {
                    "requestId": 1,
                    "position": 1,
                    "durationMillis": 20,
                    "pathPoints": [{"x": "a", "y": 0, "intensity": 1}],
                },
            )[0],
            "pathPoints[0].x='a'",
        ),
        (spellings("SdkStopByRequestId", "many")[0], "requestId='many'"),
    ],
)
def test_bad_input_names_the_field(text: str, named: str) -> None:
    with pytest.raises(BadRequest) as refused:
        parse(text)
    assert named in str(refused.value)


def test_out_of_range_values_are_clamped() -> None:
    play = parse(spellings("SdkPlay", {**PLAY, "intensity": 1e9, "duration": 0, "offsetY": -7})[0])
    assert isinstance(play, PlayEvent)
    assert (play.intensity, play.duration, play.offset_y) == (10.0, 0.05, -1.0)
    dots = parse(
        spellings(
            "SdkPlayDotMode",
            {"requestId": 1, "position": 1, "durationMillis": 10**9, "motorValues": [500] * 9},
        )[0]
    )
    assert isinstance(dots, PlayPoints)
    assert dots.duration_ms == 100_000 and dots.dots == tuple((i, 100.0) for i in range(6))


def test_server_messages_are_pascal_case_with_a_string_message() -> None:
    ready = json.loads(server_message("ServerReady", ""))
    assert ready == {"Type": "ServerReady", "Message": ""}
    events = json.loads(server_message("ServerEventList", [{"eventName": "a", "eventTime": 3}]))
    assert events["Type"] == "ServerEventList"
    assert json.loads(events["Message"]) == [{"eventName": "a", "eventTime": 3}]
    ids = json.loads(server_message("ServerActiveRequestIdList", [58147]))
    assert ids["Message"] == "[58147]"
