"""The sound card sink (PortAudio through ``sounddevice``), on a device found by
:mod:`phantomtouch.output.devices`.

``sounddevice`` is imported only when a sound card is asked for (``phantomtouch[audio]``
installs it); without it the engine falls back to the null sink.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.output.devices import (
    PERIOD_HOST_APIS,
    find_output_device,
    host_period_frames,
    sounddevice_module,
)
from phantomtouch.output.sinks import CaptureSink, NullSink, RenderFn, Sink
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger(__name__)


def resolve_period(
    host_api: str, host_period: int | None, asked: int | None, preferred: int
) -> tuple[int, int, str]:
    """The frames of each callback and of the engine's block on a PortAudio device.

    Parameters
    ----------
    host_api : str
        The device's host API (a key of :data:`PERIOD_HOST_APIS` or another).
    host_period : int or None
        Its period, frames (:func:`host_period_frames`); None: it has none.
    asked : int or None, 16 <= asked <= 8192
        The block asked for (``--period``); None: the device's period, else ``preferred``.
    preferred : int
        The device profile's ``block_frames``.

    Returns
    -------
    tuple
        ``(period_frames, block_frames, source)``: frames per callback, frames per
        engine block (``period_frames`` or, on JACK, a divisor of it), and where the
        period came from (``"backend"``, ``"option"`` or ``"profile"``).

    Raises
    ------
    ParameterError
        ``asked`` is out of range.
    DeviceError
        ``asked`` does not divide the period JACK's server runs at.
    """
    if asked is not None:
        valid = isinstance(asked, int) and not isinstance(asked, bool)
        if not valid or not limits.MIN_BLOCK_FRAMES <= asked <= limits.MAX_BLOCK_FRAMES:
            raise ParameterError(
                f"period_frames={asked!r} must be an integer in "
                f"[{limits.MIN_BLOCK_FRAMES}, {limits.MAX_BLOCK_FRAMES}]"
            )
    fixed = PERIOD_HOST_APIS.get(host_api, False)
    if host_period is not None and fixed:
        if asked is None:
            return host_period, host_period, "backend"
        if host_period % asked:
            raise DeviceError(
                f"period_frames={asked} must divide the {host_api} server's period, "
                f"{host_period} frames (start the server with that period: jackd -p {asked})"
            )
        return host_period, asked, "option"
    if asked is not None:
        return asked, asked, "option"
    if host_period is not None:
        return host_period, host_period, "backend"
    return preferred, preferred, "profile"


class SoundDeviceSink:
    """A PortAudio output stream (``sounddevice.OutputStream``), float32.

    The stream is opened here (so its ports exist, e.g. for JACK connections) and
    started by :meth:`start`.

    Its period (PortAudio ``blocksize``: the frames of each callback) and the engine's
    block are found by :func:`resolve_period`: on JACK the server's period, on ASIO, Core
    Audio and WASAPI the buffer PortAudio reports, elsewhere the profile's block.

    Parameters
    ----------
    device : DeviceProfile
        Sample rate, preferred block size and channels.
    output : int, str or None
        Device index, part of its name, or None (see :func:`find_output_device`).
    channel_map : sequence of int or None
        Sound card output (1-based) for each of the profile's channels, e.g.
        ``[3, 4, 5, 6, 7, 8, 9, 10]``; outputs not in the map stay silent. None: channel k
        on output k.
    latency : {"low", "high"} or float
        PortAudio's suggested output latency; a float is seconds, 0 < latency <= 1.
    exclusive : bool
        WASAPI exclusive mode (``sounddevice.WasapiSettings(exclusive=True)``): the
        stream alone on the device, at its own block size, bypassing Windows' mixer.
    period_frames : int or None, 16 <= period_frames <= 8192
        The engine's block asked for (``--period``): on JACK a divisor of the server's
        period, elsewhere the callback's frames; None: the device's period.

    Raises
    ------
    DeviceError
        The device is missing, has too few outputs, PortAudio cannot open it,
        ``exclusive`` is asked of a device that is not a WASAPI one, or
        ``period_frames`` does not divide JACK's period.
    ParameterError
        ``channel_map``, ``latency`` or ``period_frames`` is out of range.
    """

    backend = "sounddevice"
    realtime = True

    def __init__(
        self,
        device: DeviceProfile,
        output: int | str | None = None,
        *,
        channel_map: Sequence[int] | None = None,
        latency: float | str = "low",
        exclusive: bool = False,
        period_frames: int | None = None,
    ) -> None:
        self.sample_rate_hz = device.sample_rate_hz
        self.channels = device.channels
        self._map = self._check_map(channel_map, device.channels)
        self._check_latency(latency)
        stream_channels = int(self._map.max()) + 1 if self._map is not None else self.channels
        sd = sounddevice_module()
        found = find_output_device(output, stream_channels, exclusive=exclusive)
        self.output_device: str = found["name"]
        self.period_frames, self.block_frames, self.period_source = resolve_period(
            found["hostapi"], host_period_frames(found), period_frames, device.block_frames
        )
        self._buffer = np.zeros((self.period_frames, self.channels), dtype=np.float32)
        self._render: RenderFn | None = None
        self.underruns = 0
        self._dac_delay_s: float | None = None
        extra_settings = sd.WasapiSettings(exclusive=True) if exclusive else None
        try:
            self._stream = sd.OutputStream(
                samplerate=self.sample_rate_hz,
                blocksize=self.period_frames,
                device=found["index"],
                channels=stream_channels,
                dtype="float32",
                latency=latency,
                callback=self._callback,
                extra_settings=extra_settings,
            )
        except (sd.PortAudioError, ValueError) as exc:
            raise DeviceError(f"cannot open output device {self.output_device!r}: {exc}") from exc

    @staticmethod
    def _check_map(channel_map: Sequence[int] | None, channels: int) -> np.ndarray | None:
        if channel_map is None:
            return None
        outputs = list(channel_map)
        valid = all(isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in outputs)
        if not valid or len(outputs) != channels or len(set(outputs)) != channels:
            raise ParameterError(
                f"channel_map={channel_map!r} must list {channels} distinct outputs, each >= 1"
            )
        return np.array(outputs, dtype=np.intp) - 1

    @staticmethod
    def _check_latency(latency: float | str) -> None:
        if isinstance(latency, str) and latency in ("low", "high"):
            return
        if isinstance(latency, int | float) and not isinstance(latency, bool) and 0 < latency <= 1:
            return
        raise ParameterError(f"latency={latency!r} must be 'low', 'high' or seconds in (0, 1]")

    @property
    def output_latency_s(self) -> float:
        return float(self._stream.latency)

    def dac_delay_s(self) -> float | None:
        """Time from the current callback until its first frame reaches the converter,
        s (PortAudio's ``outputBufferDacTime - currentTime``; None before the first)."""
        return self._dac_delay_s

    def _callback(self, outdata: np.ndarray, frames: int, time_info: Any, status: Any) -> None:
        """PortAudio's callback (real time): fill ``outdata``, (frames, stream channels)."""
        self._dac_delay_s = time_info.outputBufferDacTime - time_info.currentTime
        if status.output_underflow:
            self.underruns += 1
        render = self._render
        if render is None:
            outdata.fill(0.0)
        elif self._map is None:
            render(outdata)
        else:
            if frames <= self.period_frames:
                block = self._buffer[:frames]
            else:  # PortAudio keeps the fixed blocksize; this is only a safety net
                block = np.empty((frames, self.channels), dtype=np.float32)
            render(block)
            outdata.fill(0.0)
            outdata[:, self._map] = block

    def start(self, render: RenderFn) -> None:
        """Start the stream, pulling blocks from ``render`` (non real time)."""
        self._render = render
        try:
            self._portaudio("start")
        except DeviceError:
            self._render = None
            raise

    def close(self) -> None:
        """Close the stream (non real time)."""
        self._portaudio("close")

    def _portaudio(self, action: str) -> None:
        """Call the stream's ``action`` method; a PortAudio failure is a DeviceError."""
        sd = sounddevice_module()
        try:
            getattr(self._stream, action)()
        except sd.PortAudioError as exc:
            raise DeviceError(
                f"cannot {action} output device {self.output_device!r}: {exc}"
            ) from exc


def open_default_sink(
    device: DeviceProfile,
    output: int | str | None = None,
    *,
    exclusive: bool = False,
    period_frames: int | None = None,
) -> Sink:
    """The sound card with enough outputs if there is one, else the null sink.

    Parameters
    ----------
    output, exclusive, period_frames
        As for :class:`SoundDeviceSink`: a device asked for opens or raises
        :class:`DeviceError`; with None, no device with enough outputs (or no PortAudio)
        gives a :class:`NullSink` (at ``period_frames`` when given).
    """
    try:
        return SoundDeviceSink(device, output, exclusive=exclusive, period_frames=period_frames)
    except DeviceError as exc:
        if output is not None:
            raise
        logger.info("no usable sound card (%s); using the null sink", exc)
        return NullSink(device, period_frames=period_frames)


@dataclass(frozen=True)
class SinkSpec:
    """The sink the engine process opens.

    Parameters
    ----------
    backend : {"default", "sounddevice", "null", "capture"}
        ``"default"``: :func:`open_default_sink`.
    output, channel_map, latency, exclusive
        As for :class:`SoundDeviceSink` (``output`` and ``exclusive`` also for "default").
    wav_path : str or None
        For "capture": a real-time capture sink whose recording is written to this
        float32 WAV when the engine closes.
    period_frames : int or None
        The engine's block asked for (``--period``; :class:`SoundDeviceSink`,
        :class:`NullSink`); None: the sound card's period, or the profile's block.
    """

    backend: str = "default"
    output: int | str | None = None
    channel_map: tuple[int, ...] | None = None
    latency: float | str = "low"
    wav_path: str | None = None
    exclusive: bool = False
    period_frames: int | None = None

    def __post_init__(self) -> None:
        if self.backend not in ("default", "sounddevice", "null", "capture"):
            raise ParameterError(
                f"backend={self.backend!r} must be 'default', 'sounddevice', 'null' or 'capture'"
            )

    def open(self, device: DeviceProfile) -> Sink:
        """Open the sink (in the engine process)."""
        period = self.period_frames
        if self.backend == "null":
            return NullSink(device, period_frames=period)
        if self.backend == "capture":
            return CaptureSink(device, realtime=True, wav_path=self.wav_path, period_frames=period)
        if self.backend == "sounddevice":
            return SoundDeviceSink(
                device,
                self.output,
                channel_map=self.channel_map,
                latency=self.latency,
                exclusive=self.exclusive,
                period_frames=period,
            )
        return open_default_sink(
            device, self.output, exclusive=self.exclusive, period_frames=period
        )
