"""SDK2 as games meet it: bHaptics' own ``bhaptics-python`` 0.2.0 against a real
``phantomtouch serve --bhaptics ... --output capture:FILE.wav``, and what the band played.

The game's events come from a raw client's ``SdkRequestAuthInit`` for the same workspace
(bHaptics' library 0.2.0 never sends one: the study, §6), in library 0.2.2's spelling; a
second workspace is defined in a real game's lower-case spelling. Where a point is felt
follows from the documented mapping alone (docs/bhaptics.md, "The mapping"), as in the SDK1
test: the energy centroid of the captured channels within 0.5 cm. The library's calls and
answers are what the study's table says each does (docs/bhaptics.md, "SDK2").
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from tests.bhaptics.sdk2.deployments import (
    auth_init_game,
    auth_init_library,
    game_events,
)
from tests.bhaptics.sdk2.library import PORT, library_python, run_steps
from tests.bhaptics.sdk2.raw_client import RawClient, envelope
from tests.bhaptics.test_standin_live import RELEASE_S, SILENT, TRANSIT_S, Capture, place
from tests.support.clocks import ClockReads
from tests.support.live_server import HOST, LiveServer, free_port

WORKSPACE = "phantomtest-workspace"
GAME_WORKSPACE = "into-the-test"
LENGTH_TOLERANCE_S = 0.04
"""An event sounds for its length within this (the SDK1 test's rule)."""


def steps() -> list[dict[str, Any]]:
    """Every call of the study's table, with the waits that let each be heard alone."""

    def call(name: str | None, fn: str, *args: Any, sleep_s: float = 0.0) -> dict[str, Any]:
        step: dict[str, Any] = {"call": fn, "args": list(args), "sleep_s": sleep_s}
        if name is not None:
            step["name"] = name
        return step

    return [
        call("init", "registry_and_initialize", WORKSPACE, "test-key", "", sleep_s=0.5),
        call("time_stab", "get_event_time", "stab"),
        call("time_long", "get_event_time", "long"),
        call("time_buzz", "get_event_time", "buzz"),
        call("time_unknown", "get_event_time", "no-such-event"),
        call("left", "is_bhaptics_device_connected", 1),
        call("right", "is_bhaptics_device_connected", 2),
        call("vest_device", "is_bhaptics_device_connected", 0),
        call("devices", "get_device_info_json"),
        call("mappings", "get_haptic_mappings_json"),
        # play_event: a 300 ms dot on ForearmL motor 2
        call("stab", "play_event", "stab", sleep_s=0.15),
        call("stab_playing", "is_playing_event"),
        call("stab_playing_name", "is_playing_event_by_event_id", "stab"),
        call("stab_playing_id", "is_playing_event_by_request_id", "@stab", sleep_s=0.6),
        call("stab_over", "is_playing_event"),
        call("stab_over_id", "is_playing_event_by_request_id", "@stab"),
        # play_param: duration 2 doubles it, intensity 0.5 halves it
        call("stretched", "play_param", "stab", 0.5, 2.0, 0, 0, sleep_s=1.0),
        # audio frames only; both kinds in one event
        call("buzz", "play_event", "buzz", sleep_s=0.7),
        call("mixed", "play_without_result", "mixed", 1.0, 1.0, 0, 0, sleep_s=0.7),
        # dot and path mode
        call("dot", "play_dot", 1, 300, [0, 0, 100, 0, 0, 0], sleep_s=0.6),
        call("path", "play_path", 2, 300, [0.25], [0.5], [80], sleep_s=0.6),
        # a loop: 3 times, 200 ms apart
        call("loop", "play_loop", "stab", 1.0, 1.0, 0, 0, 200, 3, sleep_s=1.8),
        # the three stops
        call("long_1", "play_event", "long", sleep_s=0.5),
        call("stop_id", "stop_by_request_id", "@long_1", sleep_s=0.05),
        call("long_1_after", "is_playing_event_by_request_id", "@long_1", sleep_s=0.5),
        call("long_2", "play_event", "long", sleep_s=0.5),
        call("stop_name", "stop_by_event_name", "long", sleep_s=0.05),
        call("long_2_after", "is_playing_event_by_event_id", "long", sleep_s=0.5),
        call("long_3", "play_event", "long"),
        call("held_dot", "play_dot", 2, 3000, [0, 0, 0, 0, 50, 0], sleep_s=0.5),
        call("stop_all", "stop_all", sleep_s=0.05),
        call("all_after", "is_playing_event", sleep_s=0.5),
        # what plays nothing on the band
        call("vest", "play_event", "vest", sleep_s=0.1),
        call("unknown", "play_event", "no-such-event", sleep_s=0.1),
        call("unknown_playing", "is_playing_event_by_event_id", "no-such-event"),
        call("foot_dot", "play_dot", 4, 300, [100, 100, 100, 100, 100, 100], sleep_s=0.6),
        # device calls: answered, nothing breaks
        call("ping", "ping", "phantomtouch-ForearmL"),
        call("ping_all", "ping_all"),
        call("swap", "swap_position", "phantomtouch-ForearmL"),
        call("vsm", "set_device_vsm", "phantomtouch-ForearmL", 3, sleep_s=0.2),
        call("reinit", "retry_initialize", WORKSPACE, "test-key", sleep_s=0.5),
        call("time_after_reinit", "get_event_time", "stab"),
        call("end", "is_playing_event", sleep_s=0.3),
        call("close", "close"),
    ]


async def define_events(url: str, game_url: str) -> dict[str, Any]:
    """Define the workspaces' events as a raw client would, in both spellings; what the
    raw clients were told."""
    told: dict[str, Any] = {}
    async with RawClient(url) as library_022:
        await library_022.expect("ServerEventNameList", 0.0)  # the greeting
        sent = await library_022.send(auth_init_library(WORKSPACE, game_events(WORKSPACE)))
        told["events"] = await library_022.expect("ServerEventList", sent)
        told["names"] = await library_022.expect("ServerEventNameList", sent)
    async with RawClient(game_url) as game:
        await game.expect("ServerEventNameList", 0.0)
        sent = await game.send(auth_init_game(GAME_WORKSPACE, game_events(GAME_WORKSPACE)))
        told["game_events"] = await game.expect("ServerEventList", sent)
        message = {"eventName": "stab", "requestId": 7, "intensity": 1, "duration": 1}
        told["game_stab"] = await game.send(envelope("SdkPlay", message, lower=True))
        told["game_active"] = await game.expect(
            "ServerActiveRequestIdList", told["game_stab"], where=lambda ids: ids == [7]
        )
        told["game_over"] = await game.expect(
            "ServerActiveRequestIdList", told["game_stab"] + 0.2, where=lambda ids: ids == []
        )
        await asyncio.sleep(0.6)
    return told


def test_bhaptics_python_plays_every_call_as_the_study_says(tmp_path: Path) -> None:
    library_python()
    wav = tmp_path / "band.wav"
    server = LiveServer(
        tmp_path / "library.db",
        output=f"capture:{wav}",
        args=("--bhaptics", f"{HOST}:{free_port()}", "--bhaptics-sdk2", f"{HOST}:{PORT}"),
        env={"XDG_DATA_HOME": str(tmp_path / "data")},
    ).start()
    base = f"wss://{HOST}:{PORT}/v3/feedback"
    try:
        device = httpx.get(f"{server.url}/device", timeout=5.0).json()
        with ClockReads(server.url) as clocks:
            told = asyncio.run(
                define_events(
                    f"{base}?workspace_id={WORKSPACE}&api_key=k&version=0.0.4",
                    f"{base}/?workspace_id={GAME_WORKSPACE}&api_key=k&version=1",
                )
            )
            records = run_steps(steps(), tmp_path)
        assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200
    finally:
        server.stop()
    band = Capture(wav, clocks, device)
    got = {r["name"]: r for r in records}

    def result(name: str) -> Any:
        return got[name]["result"]

    def at(name: str) -> float:
        return float(got[name]["sent_s"])

    # the raw clients: integer eventTime, the event's length (not the portal's 290)
    times = {e["eventName"]: e["eventTime"] for e in told["events"]}
    assert times == {"stab": 300, "buzz": 300, "mixed": 300, "long": 3000, "vest": 500}
    assert all(type(t) is int for t in times.values())
    assert told["names"] == list(times)
    assert {e["eventName"] for e in told["game_events"]} == set(times)
    assert told["game_active"] == [7]
    t = told["game_stab"]
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 1.0, 0.0)) < 0.5

    # connection, devices, event times
    assert result("init") is True
    assert (result("time_stab"), result("time_long"), result("time_buzz")) == (300, 3000, 300)
    assert result("time_unknown") == 0
    assert (result("left"), result("right"), result("vest_device")) == (True, True, False)
    assert '"position":1' in result("devices") and '"position":2' in result("devices")
    assert '"eventTime":300' in result("mappings")

    # play_event: felt at ForearmL motor 2 (x 1, y 0) for 300 ms; listed while it plays
    t = at("stab")
    assert isinstance(result("stab"), int)
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 1.0, 0.0)) < 0.5
    on, off = band.sounding(t, t + 0.7)
    assert abs((off - on) - 0.3) < LENGTH_TOLERANCE_S, off - on
    assert (result("stab_playing"), result("stab_playing_name"), result("stab_playing_id")) == (
        True,
        True,
        True,
    )
    assert (result("stab_over"), result("stab_over_id")) == (False, False)

    # play_param duration 2: twice as long; intensity 0.5: half the peak
    t = at("stretched")
    on, off = band.sounding(t, t + 1.0)
    assert abs((off - on) - 0.6) < LENGTH_TOLERANCE_S, off - on
    full = band.peak(at("stab"), at("stab") + 0.5)
    assert band.peak(t, t + 1.0) < 0.75 * full

    # audio frames: ForearmR motor 4 (x 0.5, y 1); both kinds together
    t = at("buzz")
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 0.5, 1.0)) < 0.5
    on, off = band.sounding(t, t + 0.7)
    assert abs((off - on) - 0.3) < LENGTH_TOLERANCE_S, off - on
    on, off = band.sounding(at("mixed"), at("mixed") + 0.7)
    assert abs((off - on) - 0.3) < LENGTH_TOLERANCE_S, off - on
    both = (place(device, 0.0, 0.0) + place(device, 1.0, 1.0)) / 2
    # windows clear of each voice's start: on a loaded machine one voice of an event may
    # reach the engine after its frame and start a few ms late (docs/bhaptics.md)
    assert np.linalg.norm(band.centroid(on + 0.06, on + 0.18) - both) < 0.5
    assert np.linalg.norm(band.centroid(on + 0.25, on + 0.29) - place(device, 0.0, 0.0)) < 0.5

    # dot and path mode
    t = at("dot")
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 1.0, 0.0)) < 0.5
    t = at("path")
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 0.25, 0.5)) < 0.5

    # the loop: 3 x 300 ms, 200 ms of silence between
    t = at("loop")
    on, off = band.sounding(t, t + 1.8)
    assert abs((off - on) - 1.3) < LENGTH_TOLERANCE_S, off - on
    for gap in range(2):
        start = on + 0.3 + gap * 0.5
        assert band.peak(start + 0.02, start + 0.18) <= SILENT
        assert band.peak(start + 0.22, start + 0.28) > SILENT

    # the stops: silent within the next block and the release
    stop_s = band.block_s * 2 + RELEASE_S
    for name in ("stop_id", "stop_name", "stop_all"):
        t = at(name)
        assert band.peak(t - 0.3, t - 0.05) > SILENT, f"{name}: nothing played before"
        assert band.peak(t + TRANSIT_S + stop_s, t + 0.5) <= SILENT, name
    assert (result("long_1_after"), result("long_2_after"), result("all_after")) == (
        False,
        False,
        False,
    )

    # a vest event, an unknown one, a foot's dots: nothing on the band, nothing listed
    t = at("vest")
    assert band.peak(t, at("ping")) <= SILENT
    assert isinstance(result("unknown"), int)
    assert result("unknown_playing") is False

    # device calls answered; the re-init keeps the workspace's events
    for name in ("ping", "ping_all", "swap", "vsm", "reinit"):
        assert not isinstance(result(name), dict), (name, result(name))
    assert result("time_after_reinit") == 300
    assert result("end") is False
    assert band.peak(at("end"), at("end") + 3.0) <= SILENT
