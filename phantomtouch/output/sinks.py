"""The sinks that need no audio hardware: a clocked null sink and a capture sink (the sound
card's is in :mod:`phantomtouch.output.soundcard`)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import numpy as np
import soundfile

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema.device import DeviceProfile

RenderFn = Callable[[np.ndarray], None]
"""``render(out)`` fills ``out``, shape (frames, channels), float32, with the next frames."""


class Sink(Protocol):
    """Where the engine's blocks go: once per period, the sink calls the engine's render
    function with a float32 buffer of shape (period_frames, channels) that it fills; the
    engine renders it in blocks of ``block_frames``, which divides ``period_frames``."""

    backend: str
    """``"sounddevice"``, ``"null"`` or ``"capture"``."""
    realtime: bool
    """Blocks are pulled at the pace of a clock (not by the caller)."""
    sample_rate_hz: int
    block_frames: int
    """The engine's block: ``period_frames`` or a fixed divisor of it."""
    period_frames: int
    """Frames of each call of the render function: the sound card's period (its whole
    playing time is the callback's budget)."""
    period_source: str
    """Where ``period_frames`` came from: ``"backend"`` (the audio server's or the host
    API's buffer), ``"option"`` (asked for) or ``"profile"`` (the device profile's
    ``block_frames``, for an output without a period of its own)."""
    channels: int

    @property
    def output_device(self) -> str | None:
        """Name of the sound card output, None without one."""

    @property
    def underruns(self) -> int:
        """Blocks the output needed before they were ready."""

    @property
    def output_latency_s(self) -> float:
        """Time from a block's computation to its first frame leaving the output, s."""

    def start(self, render: RenderFn) -> None:
        """Begin pulling blocks from ``render`` (non real time)."""

    def close(self) -> None:
        """Stop pulling blocks and release the output; the sink cannot be started again
        (non real time)."""


class NullSink:
    """Pulls blocks at real-time pace and drops them (no sound card): its thread renders
    one block per block period of the monotonic clock. A block is late when its period
    began more than one period ago; it then counts as an underrun and the pace restarts
    from now (a real output would have played silence).

    Parameters
    ----------
    device : DeviceProfile
        Sample rate, block size and channels.
    period_frames : int or None, 16 <= period_frames <= 8192
        Frames per block asked for (``--period``); None: the profile's ``block_frames``.

    Raises
    ------
    ParameterError
        ``period_frames`` is out of range.
    """

    backend = "null"
    realtime = True
    output_device: str | None = None
    output_latency_s = 0.0

    def __init__(self, device: DeviceProfile, *, period_frames: int | None = None) -> None:
        self.period_source = "profile" if period_frames is None else "option"
        if period_frames is not None:
            device = device.at_block(period_frames)
        self.sample_rate_hz = device.sample_rate_hz
        self.block_frames = self.period_frames = device.block_frames
        self.channels = device.channels
        self.underruns = 0
        self._period_s = self.period_frames / device.sample_rate_hz
        self._buffer = np.zeros((device.block_frames, device.channels), dtype=np.float32)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._render: RenderFn | None = None

    def start(self, render: RenderFn) -> None:
        if self._thread is not None:
            raise DeviceError(f"the {self.backend} sink is already running")
        self._render = render
        if not self.realtime:  # a capture sink pulled by hand
            return
        self._stop.clear()
        self._thread = threading.Thread(
            target=self._run, args=(render,), name=f"phantomtouch-{self.backend}-sink", daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        thread, self._thread = self._thread, None
        self._render = None
        if thread is not None:
            self._stop.set()
            thread.join()

    def close(self) -> None:
        self.stop()

    def _run(self, render: RenderFn) -> None:
        due_s = time.monotonic()
        while not self._stop.is_set():
            now_s = time.monotonic()
            if now_s < due_s:
                self._stop.wait(due_s - now_s)
                continue
            if now_s - due_s > self._period_s:
                self.underruns += 1
                due_s = now_s
            render(self._buffer)
            self._record(self._buffer)
            due_s += self._period_s

    def _record(self, block: np.ndarray) -> None:
        """Keep what the sink keeps of a block just rendered (the null sink: nothing)."""


class CaptureSink(NullSink):
    """Records every block the engine renders.

    Parameters
    ----------
    realtime : bool, default False
        False: blocks are pulled only by :meth:`pull`. True: a thread pulls them at
        real-time pace, like :class:`NullSink`.
    max_frames : int, >= 0, or None
        Stop recording (but keep pulling) after this many frames; None: no limit.
    wav_path : str, Path or None
        Write the recording to this float32 WAV when the sink closes.
    period_frames : int or None
        As for :class:`NullSink`.

    Attributes
    ----------
    frames : int
        Frames recorded so far.
    """

    backend = "capture"

    def __init__(
        self,
        device: DeviceProfile,
        *,
        realtime: bool = False,
        max_frames: int | None = None,
        wav_path: str | Path | None = None,
        period_frames: int | None = None,
    ) -> None:
        if max_frames is not None and (isinstance(max_frames, bool) or max_frames < 0):
            raise ParameterError(f"max_frames={max_frames!r} must be None or >= 0")
        super().__init__(device, period_frames=period_frames)
        self.wav_path = None if wav_path is None else Path(wav_path)
        self.realtime = bool(realtime)
        self.max_frames = max_frames
        self._blocks: list[np.ndarray] = []
        self.frames = 0
        self._lock = threading.Lock()  # the pacer's thread records, any thread reads

    def close(self) -> None:
        """Stop; with ``wav_path``, write the recording there."""
        self.stop()
        if self.wav_path is not None:
            self.write_wav(self.wav_path)

    def pull(self, blocks: int = 1) -> np.ndarray:
        """Render ``blocks`` blocks now and record them (not with ``realtime``).

        Returns
        -------
        ndarray, shape (blocks * block_frames, channels), float32
            The pulled blocks.
        """
        if self.realtime:
            raise DeviceError("a realtime CaptureSink is pulled by its own thread")
        render = self._render
        if render is None:
            raise DeviceError("the CaptureSink is not started (start the engine first)")
        pulled = [np.zeros((0, self.channels), dtype=np.float32)]
        for _ in range(blocks):
            render(self._buffer)
            self._record(self._buffer)
            pulled.append(self._buffer.copy())
        return np.concatenate(pulled)

    def _record(self, block: np.ndarray) -> None:
        keep = block.shape[0]
        if self.max_frames is not None:
            keep = max(0, min(keep, self.max_frames - self.frames))
        if keep:
            with self._lock:
                self._blocks.append(block[:keep].copy())
                self.frames += keep

    def recording(self) -> np.ndarray:
        """Everything recorded, shape (frames, channels), float32 (frame 0 = engine frame 0)."""
        with self._lock:
            blocks = [np.zeros((0, self.channels), dtype=np.float32), *self._blocks]
        return np.concatenate(blocks)

    def write_wav(self, path: str | Path) -> Path:
        """Write the recording as a float32 WAV, one channel per output channel."""
        path = Path(path)
        soundfile.write(str(path), self.recording(), self.sample_rate_hz, subtype="FLOAT")
        return path
