"""The service is one client of the audio server, not two: a real server on a real JACK
server.

``sounddevice`` opens PortAudio as it is imported, and open, PortAudio is a client of a
running JACK server. JACK wakes every client each period and the cycle waits for them
all, so the service's own process, which only looks the output device up, closes
PortAudio again before the engine process opens the device and plays
(``phantomtouch.output.devices.release_portaudio``).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import jack
import pytest

from phantomtouch import DeviceProfile
from tests.support.jack import JackServer, start_jack_or_skip
from tests.support.live_server import LiveServer

NAMES = ("PortAudio", *(f"PortAudio-{n:02d}" for n in range(1, 8)))
"""The names JACK gives PortAudio's clients, in the order they open."""


@pytest.fixture(scope="module")
def jack_128() -> Iterator[JackServer]:
    server = start_jack_or_skip(sample_rate_hz=48000, period_frames=128, channels=8)
    yield server
    server.stop()


def portaudio_clients(observer: jack.Client) -> list[str]:
    """The PortAudio clients in the server's graph now."""
    found = []
    for name in NAMES:
        try:
            observer.get_uuid_for_client_name(name)
        except jack.JackError:
            continue
        found.append(name)
    return found


def test_only_the_engine_process_is_a_client_of_jack(jack_128: JackServer, tmp_path: Path) -> None:
    profile = tmp_path / "armband-128.json"
    profile.write_text(
        DeviceProfile.default().model_copy(update={"block_frames": 128}).model_dump_json()
    )
    observer = jack.Client("observer", servername=jack_128.name, no_start_server=True)
    try:
        before = portaudio_clients(observer)  # this process's own, if it opened PortAudio
        server = LiveServer(
            tmp_path / "patterns.db", output="system", args=("--device", str(profile))
        )
        with server:
            assert httpx.get(f"{server.url}/device", timeout=10).json()["output_device"]
            during = portaudio_clients(observer)
        assert len(during) == len(before) + 1, f"before {before}, while serving {during}"
    finally:
        observer.close()
