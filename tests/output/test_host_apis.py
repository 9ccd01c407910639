"""Outputs named by host API (``ASIO:Focusrite``, ``WASAPI:Speakers``, ``JACK:system``),
WASAPI's exclusive mode, and ASIO asked of sounddevice's bundled PortAudio on Windows.

The host APIs of Windows and macOS are not on this machine: their names are checked
against the names PortAudio gives them, and the lookup runs against JACK's dummy device.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from phantomtouch import DeviceProfile
from phantomtouch.cli import main
from phantomtouch.errors import DeviceError
from phantomtouch.output.devices import find_output_device, split_host_api
from phantomtouch.output.soundcard import SoundDeviceSink
from tests.support.jack import JackServer

WINDOWS = ["MME", "Windows DirectSound", "ASIO", "Windows WASAPI", "Windows WDM-KS"]
"""PortAudio's host API names on Windows (sounddevice's bundled DLL, ASIO enabled)."""
MACOS = ["Core Audio"]
LINUX = ["ALSA", "JACK Audio Connection Kit", "OSS"]


@pytest.mark.parametrize(
    ("output", "host_apis", "expected"),
    [
        ("ASIO:Focusrite USB ASIO", WINDOWS, ("ASIO", "Focusrite USB ASIO")),
        ("wasapi:Speakers (MOTU M4)", WINDOWS, ("Windows WASAPI", "Speakers (MOTU M4)")),
        ("WDM-KS:Speakers", WINDOWS, ("Windows WDM-KS", "Speakers")),
        ("ASIO:", WINDOWS, ("ASIO", "")),
        ("CoreAudio:Aggregate Device", MACOS, ("Core Audio", "Aggregate Device")),
        ("core audio:MOTU", MACOS, ("Core Audio", "MOTU")),
        ("JACK:system", LINUX, ("JACK Audio Connection Kit", "system")),
        # a colon that names no host API is part of the device's name
        (
            "HDA Intel PCH: ALC892 Analog (hw:0,0)",
            LINUX,
            (None, "HDA Intel PCH: ALC892 Analog (hw:0,0)"),
        ),
        ("hw:0,0", LINUX, (None, "hw:0,0")),
        # a prefix that fits several host APIs names none of them
        ("Windows:Speakers", WINDOWS, (None, "Windows:Speakers")),
        ("ASIO:Focusrite", MACOS, (None, "ASIO:Focusrite")),
    ],
)
def test_a_host_api_prefix_is_split_off_the_name(
    output: str, host_apis: list[str], expected: tuple[str | None, str]
) -> None:
    assert split_host_api(output, host_apis) == expected


def test_an_output_is_found_by_its_host_api(jack_server: JackServer) -> None:
    system = find_output_device("system", 8)
    assert system["hostapi"] == "JACK Audio Connection Kit"
    assert find_output_device("JACK:system", 8)["index"] == system["index"]
    assert find_output_device("jack:SYS", 8)["index"] == system["index"]
    assert find_output_device("JACK:", 8)["index"] == system["index"]  # its first that fits
    with pytest.raises(DeviceError, match=r"output='JACK:nothing' matches no output device"):
        find_output_device("JACK:nothing", 8)
    with pytest.raises(DeviceError, match=r"no JACK Audio Connection Kit device has 16"):
        find_output_device("JACK:", 16)


def test_exclusive_mode_is_refused_on_a_device_that_is_not_wasapi(
    jack_server: JackServer,
) -> None:
    with pytest.raises(DeviceError, match=r"exclusive mode is WASAPI's.*'system' is a JACK"):
        SoundDeviceSink(DeviceProfile.default(), "JACK:system", exclusive=True)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--output", "JACK:nothing"], "output='JACK:nothing' matches no output device"),
        (["--output", "system", "--exclusive"], "exclusive mode is WASAPI's"),
    ],
)
def test_serve_refuses_an_output_it_cannot_open_in_one_line(
    jack_server: JackServer,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    flags: list[str],
    message: str,
) -> None:
    argv = ["serve", "--port", "8765", "--db", str(tmp_path / "p.db"), *flags]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "", "nothing starts"
    assert len(captured.err.splitlines()) == 1 and message in captured.err, captured.err


def test_the_devices_command_names_each_outputs_host_api_and_channels(
    jack_server: JackServer, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if "system" in line)
    assert "8 outputs" in line and "JACK Audio Connection Kit" in line
    assert "HOSTAPI:NAME" in out


def test_asio_is_asked_for_before_sounddevice_is_imported_on_windows() -> None:
    """sounddevice reads ``SD_ENABLE_ASIO`` once, as it loads its bundled PortAudio."""
    script = (
        "import os, sys\n"
        "from phantomtouch.output import devices\n"
        "from phantomtouch.errors import DeviceError\n"
        "os.environ.pop('SD_ENABLE_ASIO', None)\n"
        "sys.modules.pop('sounddevice', None)\n"
        "sys.platform = 'win32'\n"
        "try:\n"
        "    devices.sounddevice_module()\n"
        "except DeviceError:\n"
        "    pass  # the Windows DLL is not on this machine\n"
        "print(os.environ.get('SD_ENABLE_ASIO'))\n"
    )
    windows = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert windows.stdout.strip() == "1", windows.stderr
    elsewhere = script.replace("sys.platform = 'win32'\n", "")
    other = subprocess.run(
        [sys.executable, "-c", elsewhere], capture_output=True, text=True, timeout=60, check=True
    )
    assert other.stdout.strip() == "None", other.stderr
