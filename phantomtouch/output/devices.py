"""The sound card's output devices as PortAudio lists them (through ``sounddevice``):
listing, lookup by index, name or host API, and the period a host API reports.

``sounddevice`` is imported only when a sound card is asked for (``phantomtouch[audio]``
installs it). Nothing here plays: the sound card sink
(:mod:`phantomtouch.output.soundcard`) opens the device found here.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any

from phantomtouch.errors import DeviceError, ParameterError, install_hint
from phantomtouch.schema import limits


def sounddevice_module() -> ModuleType:
    """``sounddevice``, on Windows with its bundled PortAudio's ASIO drivers listed."""
    if sys.platform == "win32":  # read once, at the import
        os.environ.setdefault("SD_ENABLE_ASIO", "1")
    try:
        import sounddevice
    except ImportError as exc:
        raise DeviceError(
            f"sound card output needs sounddevice, the audio extra: {install_hint('audio')}"
        ) from exc
    except OSError as exc:  # the PortAudio library itself is missing
        raise DeviceError(f"PortAudio is not available: {exc}") from exc
    if sounddevice._initialized == 0:  # released by release_portaudio: open it again
        sounddevice._initialize()
    return sounddevice


def release_portaudio() -> None:
    """Close PortAudio in this process if it is open (the service's own process, once it
    has looked the device up: the engine process plays); :func:`sounddevice_module` opens
    it again.

    Open, PortAudio is a client of a JACK server (``sounddevice`` opens it as it is
    imported). JACK wakes every client each period and the cycle waits for them all: an
    idle one is one more thread that must be scheduled in time, or the period is lost.
    """
    sd = sys.modules.get("sounddevice")
    if sd is not None and sd._initialized > 0:
        sd._terminate()


def list_output_devices() -> list[dict[str, Any]]:
    """Every PortAudio device with outputs.

    Returns
    -------
    list of dict
        ``index`` (int, for ``output=``), ``name`` (str), ``max_output_channels`` (int),
        ``default_samplerate`` (float, Hz), ``hostapi`` (str), ``default`` (bool: the
        system's default output), ``low_latency_s`` (float: PortAudio's default low
        output latency, s; on JACK one server period).

    Raises
    ------
    DeviceError
        ``sounddevice`` or PortAudio is not installed, or PortAudio fails.
    """
    sd = sounddevice_module()
    try:
        devices = sd.query_devices()
        hostapis = sd.query_hostapis()
        default_output = sd.default.device[1]
    except sd.PortAudioError as exc:
        raise DeviceError(f"cannot list output devices: {exc}") from exc
    return [
        {
            "index": index,
            "name": str(info["name"]),
            "max_output_channels": int(info["max_output_channels"]),
            "default_samplerate": float(info["default_samplerate"]),
            "hostapi": str(hostapis[info["hostapi"]]["name"]),
            "default": index == default_output,
            "low_latency_s": float(info["default_low_output_latency"]),
        }
        for index, info in enumerate(devices)
        if info["max_output_channels"] > 0
    ]


def _squeezed(name: str) -> str:
    return "".join(name.lower().split()).replace("-", "")


def split_host_api(output: str, host_apis: Sequence[str]) -> tuple[str | None, str]:
    """``HOSTAPI:NAME`` as (host API, name); (None, output) when the part before the first
    colon names none of ``host_apis`` (device names have colons too: ``hw:0,0``).

    A host API is named by a case-insensitive part of its name, spaces and hyphens
    ignored: ``WASAPI`` is ``Windows WASAPI``, ``CoreAudio`` is ``Core Audio``.
    """
    prefix, colon, name = output.partition(":")
    if not colon or not prefix.strip():
        return None, output
    wanted = _squeezed(prefix)
    matches = [api for api in host_apis if wanted in _squeezed(api)]
    chosen = [api for api in matches if _squeezed(api) == wanted] or matches
    return (chosen[0], name.strip()) if len(chosen) == 1 else (None, output)


def find_output_device(
    output: int | str | None, channels: int, *, exclusive: bool = False
) -> dict[str, Any]:
    """The output device to open, as listed by :func:`list_output_devices`.

    Parameters
    ----------
    output : int, str or None
        A device index, a (case-insensitive) part of its name, ``HOSTAPI:NAME`` (that
        part of a name among the devices of that host API; ``HOSTAPI:`` alone: its
        first device with enough outputs), or None: the default output if it has
        enough outputs, else the first device that has.
    channels : int
        Outputs needed.
    exclusive : bool
        It is to be opened in WASAPI's exclusive mode: it must be a WASAPI device.

    Raises
    ------
    DeviceError
        No such device, several match the name, it has fewer than ``channels`` outputs,
        or ``exclusive`` is asked of a device that is not a WASAPI one.
    """
    devices = list_output_devices()
    asked, host_api = output, None
    if isinstance(output, str):
        host_api, output = split_host_api(output, sorted({d["hostapi"] for d in devices}))
        if host_api is not None:
            devices = [d for d in devices if d["hostapi"] == host_api]
            output = output or None
    if output is None:
        suitable = [d for d in devices if d["max_output_channels"] >= channels]
        if not suitable:
            within = "output" if host_api is None else host_api
            raise DeviceError(
                f"output={asked!r}: no {within} device has {channels} or more outputs"
            )
        # a host API alone: its first device; None: the default output first
        return next((d for d in suitable if d["default"] and host_api is None), suitable[0])
    if isinstance(output, bool) or not isinstance(output, int | str):
        raise ParameterError(f"output={output!r} must be a device index, a name or None")
    if isinstance(output, int):
        matches = [d for d in devices if d["index"] == output]
    else:
        exact = [d for d in devices if d["name"].lower() == output.lower()]
        matches = exact or [d for d in devices if output.lower() in d["name"].lower()]
    if not matches:
        names = ", ".join(f"{d['index']}: {d['name']}" for d in devices) or "none"
        raise DeviceError(f"output={asked!r} matches no output device (outputs: {names})")
    if len(matches) > 1:
        names = ", ".join(f"{d['index']}: {d['name']} ({d['hostapi']})" for d in matches)
        raise DeviceError(
            f"output={asked!r} matches several devices ({names}); give an index or HOSTAPI:NAME"
        )
    found = matches[0]
    if found["max_output_channels"] < channels:
        raise DeviceError(
            f"output device {found['name']!r} has {found['max_output_channels']} outputs; "
            f"{channels} needed"
        )
    if exclusive and "wasapi" not in found["hostapi"].lower():
        raise DeviceError(
            f"exclusive mode is WASAPI's; output device {found['name']!r} is a "
            f"{found['hostapi']} device (name a WASAPI one: 'WASAPI:{found['name']}')"
        )
    return found


PERIOD_HOST_APIS = {
    "JACK Audio Connection Kit": True,
    "ASIO": False,
    "Core Audio": False,
    "Windows WASAPI": False,
}
"""Host APIs whose reported low output latency is one buffer of the sound card (its
period), and whether the audio server fixes it (True: JACK's ``-p``, which PortAudio
cannot change; False: PortAudio opens the buffer at the block size asked). Others (ALSA,
MME, DirectSound, ...) report a latency that is no buffer: the profile's block is used."""


def host_period_frames(found: dict[str, Any]) -> int | None:
    """The period of an output device of :func:`list_output_devices`, frames at its
    default sample rate: its low latency when its host API reports a buffer there
    (:data:`PERIOD_HOST_APIS`) and it is a block size the engine can play, else None."""
    if found["hostapi"] not in PERIOD_HOST_APIS:
        return None
    frames = round(found["low_latency_s"] * found["default_samplerate"])
    return frames if limits.MIN_BLOCK_FRAMES <= frames <= limits.MAX_BLOCK_FRAMES else None
