"""The stand-in as a game meets it: a real ``phantomtouch serve --bhaptics`` process, a
client written from the protocol study (:mod:`tests.bhaptics.player_client`, no project
code), and what the band played, read from ``--output capture:FILE.wav``.

Where a point should be felt follows from the documented mapping alone (docs/bhaptics.md,
"The mapping"): a Tactosy layout's ``x`` runs along the band from its first actuator ring
to its last, ``y`` around it from its first actuator column to its last; the actuators'
places come from ``GET /device``. Under the power law a phantom's energy is shared by its
triangle's actuators in barycentric proportion, so the energy centroid of the captured
channels is the phantom's place (0.5 cm allowed).

Times: the server clock is ``time.monotonic()`` on this machine, ``GET /clock`` pairs it
with the engine's frame count, and the capture holds one sample per engine frame from
frame 0, so a client-side time becomes a sample index.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import soundfile

from tests.bhaptics.player_client import PlayerClient
from tests.support.clocks import Clock, ClockReads, placed
from tests.support.live_server import HOST, LiveServer, free_port

CORPUS = (
    Path(__file__).resolve().parents[1] / "clips" / "samples" / "tact" / "bhaptics-popone-support"
)
RELEASE_S = 0.08
"""The release ramp of a stopped touch or a lifted contact (docs/engine.md)."""
TRANSIT_S = 0.1
"""A client knows only when it sent a message; on a loaded machine the message may take
this long to reach the engine (a close: the server answers the handshake the client waits
for before the connection's handler has it). A stop or a close by message is checked
silent from its send time plus this, the next block and the release."""
SILENT = 1e-6
"""A sample this small is silence (the capture is float32, silence is exact zero)."""


def dot_project(position: str, index: int, length_ms: int) -> dict[str, Any]:
    """A Designer project (study §3.1): one effect, one dot on for its whole length."""
    feedback = {
        "startTime": 0,
        "endTime": length_ms,
        "playbackType": "NONE",
        "pointList": [{"index": index, "intensity": 1.0}],
    }
    return {
        "layout": {"type": "Tactosy2", "layouts": {}},
        "tracks": [
            {
                "enable": True,
                "effects": [
                    {
                        "startTime": 0,
                        "offsetTime": length_ms,
                        "modes": {
                            position: {
                                "mode": "DOT_MODE",
                                "dotMode": {"dotConnected": False, "feedback": [feedback]},
                                "pathMode": {"feedback": []},
                            }
                        },
                    }
                ],
            }
        ],
    }


def tact_python_project(project: dict[str, Any]) -> dict[str, Any]:
    """Old tact-python's spelling: ``Project`` holds ``Tracks`` and ``Layout``."""
    return {"Tracks": project["tracks"], "Layout": project["layout"]}


class Capture:
    """The captured band output, and the clocks that place client times in it
    (:mod:`tests.support.clocks`)."""

    def __init__(self, wav: Path, clocks: Sequence[Clock], device: dict[str, Any]) -> None:
        samples, self.rate_hz = soundfile.read(wav, dtype="float64", always_2d=True)
        self.samples = np.asarray(samples)
        self.clocks = list(clocks)
        self.block_s = device["block_frames"] / self.rate_hz
        actuators = device["actuators"]
        self.channels = [a["channel"] - 1 for a in actuators]
        self.places = np.array([(a["x_cm"], a["y_cm"]) for a in actuators])

    def index(self, at_s: float, clock: Clock) -> int:
        """The frame at server time ``at_s``, placed by ``clock``."""
        frame = clock["frames"] + (at_s - clock["server_time_s"]) * self.rate_hz
        return max(0, min(len(self.samples), round(frame)))

    def start(self, at_s: float) -> int:
        """The first frame of a span that starts at server time ``at_s``."""
        return self.index(at_s, placed(self.clocks, at_s, at_s)[0])

    def end(self, at_s: float) -> int:
        """The frame after a span that ends at server time ``at_s``."""
        return self.index(at_s, placed(self.clocks, at_s, at_s)[1])

    def window(self, start_s: float, end_s: float) -> np.ndarray:
        """The samples from ``start_s`` to ``end_s``, each end placed by its nearest clock
        on the span's side (:func:`tests.support.clocks.placed`)."""
        return self.samples[self.start(start_s) : self.end(end_s)]

    def between(self, start_s: float, end_s: float, began: Clock, ended: Clock) -> np.ndarray:
        """The samples from ``start_s`` to ``end_s``, placed by the clocks given."""
        return self.samples[self.index(start_s, began) : self.index(end_s, ended)]

    def centroid(self, start_s: float, end_s: float) -> np.ndarray:
        energy = np.sum(self.window(start_s, end_s)[:, self.channels] ** 2, axis=0)
        assert energy.sum() > 0, "nothing was felt there"
        return np.asarray(energy @ self.places / energy.sum())

    def peak(self, start_s: float, end_s: float, clock: Clock | None = None) -> float:
        """The loudest sample from ``start_s`` to ``end_s``, placed by ``clock`` (None: by
        the nearest clocks, as :meth:`window`)."""
        block = (
            self.window(start_s, end_s)
            if clock is None
            else self.between(start_s, end_s, clock, clock)
        )
        return float(np.max(np.abs(block))) if block.size else 0.0

    def sounding(self, start_s: float, end_s: float) -> tuple[float, float]:
        """First and last time in the window where anything sounds, placed back on the
        server clock by the clock that placed the window's start."""
        began = placed(self.clocks, start_s, start_s)[0]
        first = self.index(start_s, began)
        loud = np.flatnonzero(
            np.max(np.abs(self.samples[first : self.end(end_s)]), axis=1) > SILENT
        )
        assert loud.size, "silent throughout"
        offset_s = began["frames"] / self.rate_hz - began["server_time_s"]
        return (
            (first + loud[0]) / self.rate_hz - offset_s,
            (first + loud[-1]) / self.rate_hz - offset_s,
        )


def place(device: dict[str, Any], x: float, y: float) -> np.ndarray:
    """Where the documented mapping puts layout point (x, y): x along the band's actuator
    span (y_cm), y around it (x_cm)."""
    xs = [a["x_cm"] for a in device["actuators"]]
    ys = [a["y_cm"] for a in device["actuators"]]
    return np.array((min(xs) + y * (max(xs) - min(xs)), min(ys) + x * (max(ys) - min(ys))))


async def scenario(url: str, ws_base: str, marks: dict[str, Any]) -> None:
    """Every message type in every spelling; ``marks`` gets the times to check."""
    async with (
        PlayerClient(f"{ws_base}?app_id=phantomtest&app_name=phantomtest") as lib,
        PlayerClient(ws_base) as cpp,
        PlayerClient(ws_base + "/") as tact_python,
    ):
        # C++: PascalCase, integer position, both arrays always present
        marks["dot"], status = await cpp.send(
            {
                "Register": [],
                "Submit": [
                    {
                        "Type": "frame",
                        "Key": "dot",
                        "Frame": {
                            "DurationMillis": 300,
                            "Position": 10,
                            "Texture": 0,
                            "DotPoints": [{"Index": 2, "Intensity": 100}],
                            "PathPoints": [],
                        },
                    }
                ],
            }
        )
        assert "dot" in status["ActiveKeys"]
        assert status["Status"]["ForearmL"][2] == 100
        await asyncio.sleep(0.5)

        # tact-python: camelCase frame, name position
        marks["path"], _ = await tact_python.send(
            {
                "Submit": [
                    {
                        "Type": "frame",
                        "Key": "path",
                        "Frame": {
                            "position": "ForearmR",
                            "dotPoints": [],
                            "pathPoints": [{"x": 0.25, "y": 0.5, "intensity": 80, "motorCount": 3}],
                            "durationMillis": 300,
                        },
                    }
                ]
            }
        )
        await asyncio.sleep(0.5)

        # bHapticsLib: lowercase keys, no dotPoints array; a game moving a point at 50 Hz
        glide_start = None
        for step in range(50):
            sent, _ = await lib.send(
                {
                    "Submit": [
                        {
                            "type": "frame",
                            "key": "glide",
                            "Frame": {
                                "position": "ForearmL",
                                "pathPoints": [
                                    {"x": step / 49, "y": 0.0, "intensity": 60, "motorCount": 3}
                                ],
                                "durationMillis": 100,
                            },
                        }
                    ]
                }
            )
            glide_start = glide_start or sent
            await asyncio.sleep(0.02)
        marks["glide"] = (glide_start, sent)
        await asyncio.sleep(0.5)

        # Register in all three spellings, then a key stretched by scaleOption under an altKey
        short = dot_project("ForearmL", 0, 300)
        corpus = json.loads((CORPUS / "Arm" / "Climbing_L.tact").read_text("utf-8-sig"))
        await lib.send({"Register": [{"key": "short", "project": short}]})
        await cpp.send({"Register": [{"Key": "climb", "Project": corpus["project"]}], "Submit": []})
        _, status = await tact_python.send(
            {"Register": [{"Key": "short", "Project": tact_python_project(short)}]}
        )
        assert "short" in status["RegisteredKeys"]
        marks["stretched"], status = await lib.send(
            {
                "Submit": [
                    {
                        "type": "key",
                        "key": "short",
                        "Parameters": {
                            "altKey": "short#2",
                            "scaleOption": {"intensity": 1.0, "duration": 2.0},
                            "rotationOption": {"offsetAngleX": 0, "offsetY": 0},
                        },
                    }
                ]
            }
        )
        assert "short#2" in status["ActiveKeys"]
        await asyncio.sleep(1.0)
        marks["stretched_listed"] = lib.active_between(marks["stretched"], marks["stretched"] + 0.5)
        marks["stretched_after"] = lib.statuses[-1][1]["ActiveKeys"]

        # turnOff one playback
        long = dot_project("ForearmL", 1, 3000)
        await cpp.send({"Register": [{"Key": "long", "Project": long}], "Submit": []})
        await cpp.send({"Register": [], "Submit": [{"Type": "key", "Key": "long"}]})
        await asyncio.sleep(0.4)
        _, status = await cpp.send({"Register": [], "Submit": [{"Type": "turnOff", "Key": "long"}]})
        marks["turn_off"] = cpp.statuses[-1][0]
        assert "long" not in status["ActiveKeys"]
        await asyncio.sleep(0.5)

        # turnOffAll stops keys and frames alike
        await lib.send({"Register": [{"key": "long", "project": long}]})
        await lib.send(
            {
                "Submit": [
                    {"type": "key", "key": "long", "Parameters": {"altKey": "a"}},
                    {"type": "key", "key": "long", "Parameters": {"altKey": "b"}},
                    {
                        "type": "frame",
                        "key": "held",
                        "Frame": {
                            "position": "ForearmR",
                            "dotPoints": [{"index": 4, "intensity": 50}],
                            "durationMillis": 3000,
                        },
                    },
                ]
            }
        )
        await asyncio.sleep(0.4)
        _, status = await lib.send({"Submit": [{"type": "turnOffAll"}]})
        marks["turn_off_all"] = lib.statuses[-1][0]
        assert status["ActiveKeys"] == []
        await asyncio.sleep(0.5)

        # a vest-only key and a vest frame: nothing on the arm band
        marks["vest"], _ = await tact_python.send(
            {"Register": [{"Key": "vest", "Project": dot_project("VestFront", 3, 500)}]}
        )
        await tact_python.send({"Submit": [{"Type": "key", "Key": "vest"}]})
        await tact_python.send(
            {
                "Submit": [
                    {
                        "Type": "frame",
                        "Key": "vestframe",
                        "Frame": {
                            "position": 201,
                            "dotPoints": [{"index": 3, "intensity": 100}],
                            "durationMillis": 400,
                        },
                    }
                ]
            }
        )
        # past the vest's 0.7 s window with room to spare: a frame is shown at the next
        # block, which the capture output holds ahead of the wall clock by its buffer
        await asyncio.sleep(1.0)

        # the SDKs' 4 s ping: an empty frame on FootL, answered with a status
        _, status = await cpp.send(
            {
                "Register": [],
                "Submit": [
                    {
                        "Type": "frame",
                        "Key": "ping",
                        "Frame": {
                            "Position": "FootL",
                            "DotPoints": [],
                            "PathPoints": [],
                            "DurationMillis": 100,
                        },
                    }
                ],
            }
        )
        assert status["ConnectedPositions"] == ["ForearmL", "ForearmR"]

        # bad input: each answered with a status, the connection stays
        marks["bad"] = (await lib.send("not json"))[0]
        await lib.send("\ufeff" + json.dumps({"Submit": 5}))
        await lib.send({"Submit": [{"type": "key", "key": "never-registered"}]})
        await lib.send({"Submit": [{"type": "explode", "key": "x"}]})
        await lib.send(
            {
                "Submit": [
                    {
                        "type": "frame",
                        "key": "wild",
                        "Frame": {
                            "position": "ForearmL",
                            "dotPoints": [
                                {"index": 99, "intensity": 100},
                                {"index": "3", "intensity": "1e9"},
                            ],
                            "durationMillis": "200",
                        },
                    }
                ]
            }
        )
        await asyncio.sleep(0.6)
        marks["end"] = time.monotonic()


def test_every_spelling_and_message_type_as_the_capture_shows(tmp_path: Path) -> None:
    wav = tmp_path / "band.wav"
    port = free_port()
    server = LiveServer(
        tmp_path / "library.db",
        output=f"capture:{wav}",
        args=("--bhaptics", f"{HOST}:{port}"),
    ).start()
    marks: dict[str, Any] = {}
    try:
        device = httpx.get(f"{server.url}/device", timeout=5.0).json()
        with ClockReads(server.url) as clocks:
            asyncio.run(scenario(server.url, f"ws://{HOST}:{port}/v2/feedbacks", marks))
        assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200
    finally:
        server.stop()
    band = Capture(wav, clocks, device)
    stop_s = band.block_s * 2 + RELEASE_S  # the next block, then the release ramp

    # the dot frame: ForearmL index 2 (x 1, y 0), felt at the band's far end, first column
    t = marks["dot"]
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 1.0, 0.0)) < 0.5
    # the path frame: ForearmR (0.25, 0.5), a phantom between actuators
    t = marks["path"]
    assert np.linalg.norm(band.centroid(t + 0.1, t + 0.25) - place(device, 0.25, 0.5)) < 0.5

    # the glide: it moves along the band without restarting (no gap in the sound)
    start, end = marks["glide"]
    envelope = np.max(np.abs(band.window(start + 0.05, end)), axis=1)
    blocks = envelope[: len(envelope) // 480 * 480].reshape(-1, 480).max(axis=1)
    assert blocks.min() > 0.5 * np.median(blocks), "the phantom stopped or restarted"
    first, last = band.centroid(start + 0.02, start + 0.15), band.centroid(end - 0.1, end)
    assert last[1] - first[1] > 8.0, (first, last)

    # the stretched key: 300 ms x 2, listed under its altKey while it plays
    t = marks["stretched"]
    on, off = band.sounding(t, t + 1.0)
    assert abs((off - on) - 0.6) < 0.04, off - on
    assert "short#2" in marks["stretched_listed"]
    assert "short#2" not in marks["stretched_after"]

    # turnOff and turnOffAll: silent within the next block and the release
    for mark in ("turn_off", "turn_off_all"):
        t = marks[mark]
        assert band.peak(t - 0.3, t - 0.05) > SILENT, f"{mark}: nothing played before"
        assert band.peak(t + TRANSIT_S + stop_s, t + 0.45) <= SILENT, mark

    # the vest: nothing on the arm band
    t = marks["vest"]
    assert band.peak(t, t + 0.7) <= SILENT

    # bad input: the wild frame plays clamped, under the ceiling; nothing stays on
    t = marks["bad"]
    assert band.peak(t, marks["end"]) <= 1.0
    assert band.peak(marks["end"] - 0.2, marks["end"]) <= SILENT
    assert band.peak(marks["end"], marks["end"] + 5.0) <= SILENT
