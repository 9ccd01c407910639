"""The sound card sink, device lookup and ``phantomtouch devices`` over JACK's dummy device."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from phantomtouch import DeviceProfile, ParameterError, TouchPattern, render
from phantomtouch.cli import main
from phantomtouch.engine import Engine
from phantomtouch.errors import DeviceError
from phantomtouch.output.devices import find_output_device, list_output_devices
from phantomtouch.output.sinks import NullSink
from phantomtouch.output.soundcard import SoundDeviceSink, open_default_sink
from phantomtouch.schema import Actuator
from tests.support.jack import JackRecorder, JackServer

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
SIXTEEN = DeviceProfile(  # three actuators, the last wired to output 16
    actuators=[
        Actuator(x_cm=0, y_cm=0, channel=1),
        Actuator(x_cm=1, y_cm=0, channel=2),
        Actuator(x_cm=0, y_cm=1, channel=16),
    ]
)


def test_the_jack_device_is_listed_with_its_outputs(jack_server: JackServer) -> None:
    devices = list_output_devices()
    system = [d for d in devices if d["name"] == "system"]
    assert len(system) == 1
    assert system[0]["max_output_channels"] == 8
    assert system[0]["hostapi"] == "JACK Audio Connection Kit"
    assert find_output_device("SYS", 8)["index"] == system[0]["index"]  # part of the name
    assert find_output_device(system[0]["index"], 8)["name"] == "system"


@pytest.mark.parametrize(
    ("output", "channels", "message"),
    [
        ("no such card", 8, "matches no output device"),
        (9999, 8, "matches no output device"),
        ("system", 16, "has 8 outputs; 16 needed"),
    ],
)
def test_unusable_outputs_raise_device_error(
    jack_server: JackServer, output: int | str, channels: int, message: str
) -> None:
    with pytest.raises(DeviceError, match=message):
        find_output_device(output, channels)


def test_the_default_sink_is_the_sound_card_when_it_has_enough_outputs(
    jack_server: JackServer,
) -> None:
    sink = open_default_sink(DEVICE)
    assert isinstance(sink, SoundDeviceSink) and sink.output_device == "system"
    sink.close()
    fallback = open_default_sink(SIXTEEN)  # needs 16 outputs: none has them
    assert isinstance(fallback, NullSink)
    with pytest.raises(DeviceError, match="16 needed"):
        open_default_sink(SIXTEEN, "system")


def test_bad_sink_settings_are_refused(jack_server: JackServer) -> None:
    with pytest.raises(ParameterError, match="channel_map="):
        SoundDeviceSink(DEVICE, "system", channel_map=[1, 2, 3])
    with pytest.raises(ParameterError, match="channel_map="):
        SoundDeviceSink(DEVICE, "system", channel_map=[1, 1, 2, 3, 4, 5, 6, 7])
    with pytest.raises(ParameterError, match="latency="):
        SoundDeviceSink(DEVICE, "system", latency="fast")


def test_a_channel_map_routes_each_channel_to_its_output(jack_server: JackServer) -> None:
    pattern = TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[0, 0], [0, 14.4]]}, "speed_cm_s": 60}
    )
    reversed_outputs = [8, 7, 6, 5, 4, 3, 2, 1]
    sink = SoundDeviceSink(DEVICE, "system", channel_map=reversed_outputs)
    recorder = JackRecorder(jack_server, max_frames=5 * 48000)
    recorder.connect_from("PortAudio")
    engine = Engine(DEVICE, sink)
    job = engine.schedule(pattern, start_frame=0)
    engine.start()
    deadline = time.monotonic() + 10
    while engine.job_state(job.job_id).state != "finished":  # type: ignore[union-attr]
        assert time.monotonic() < deadline
        time.sleep(0.01)
    engine.close()
    recording = recorder.close()
    reference = render(pattern, DEVICE)
    at = int(np.flatnonzero(recording.any(axis=1))[0]) - int(
        np.flatnonzero(reference.any(axis=1))[0]
    )
    np.testing.assert_array_equal(recording[at : at + len(reference)], reference[:, ::-1])


def test_the_devices_command_marks_outputs_with_enough_channels(
    jack_server: JackServer, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["devices"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(line.startswith("*") and "system" in line and "8 outputs" in line for line in lines)
    assert main(["devices", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    system = next(d for d in listed if d["name"] == "system")
    assert system["enough_outputs"] is True
