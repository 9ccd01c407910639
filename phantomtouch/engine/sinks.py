"""Sinks pull blocks from the engine: a clocked null sink and a capture sink.

A sink calls the engine's render function with a float32 buffer of shape
(block_frames, channels) that the function fills entirely, once per block. The sound card
sink lives in :mod:`phantomtouch.engine.soundcard`; this module has the two that need no
audio hardware:

- :class:`NullSink`: a thread pulls blocks at real-time pace from the monotonic clock and
  drops them; the engine's default when no sound card with enough outputs exists.
- :class:`CaptureSink`: records every block, for tests and for writing what was played
  to a WAV file. Blocks are pulled by :meth:`CaptureSink.pull` (as fast as the caller
  likes, deterministic) or, with ``realtime=True``, by a thread like the null sink's.
"""

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
    """Where the engine's blocks go.

    Attributes
    ----------
    backend : str
        ``"sounddevice"``, ``"null"`` or ``"capture"``.
    output_device : str or None
        Name of the sound card output, None without one.
    realtime : bool
        Blocks are pulled at the pace of a clock (not by the caller).
    sample_rate_hz, block_frames, channels : int
    """

    backend: str
    realtime: bool
    sample_rate_hz: int
    block_frames: int
    channels: int

    @property
    def output_device(self) -> str | None: ...

    @property
    def underruns(self) -> int:
        """Blocks the output needed before they were ready."""
        ...

    @property
    def output_latency_s(self) -> float:
        """Time from a block's computation to its first frame leaving the output, s."""
        ...

    def start(self, render: RenderFn) -> None:
        """Begin pulling blocks from ``render``."""
        ...

    def stop(self) -> None:
        """Stop pulling blocks (the output falls silent)."""
        ...

    def close(self) -> None:
        """Release the output; the sink cannot be started again."""
        ...


class _Pacer:
    """A thread that renders one block per block period of the monotonic clock.

    A block is late when its period began more than one period ago; it then counts as
    an underrun and the pace restarts from now (a real output would have played silence).
    """

    def __init__(self, name: str, device: DeviceProfile, on_block: RenderFn | None) -> None:
        self._name = name
        self._period_s = device.block_frames / device.sample_rate_hz
        self._buffer = np.zeros((device.block_frames, device.channels), dtype=np.float32)
        self._on_block = on_block
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.underruns = 0

    def start(self, render: RenderFn) -> None:
        if self._thread is not None:
            raise DeviceError(f"{self._name} is already running")
        self._stop.clear()
        self._thread = threading.Thread(
            target=self._run, args=(render,), name=self._name, daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()
            thread.join()

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
            if self._on_block is not None:
                self._on_block(self._buffer)
            due_s += self._period_s


class _PacedSink:
    """What the sinks paced by a :class:`_Pacer` share: no device, no latency, the
    pacer's underruns."""

    _pacer: _Pacer

    @property
    def output_device(self) -> str | None:
        return None

    @property
    def underruns(self) -> int:
        return self._pacer.underruns

    @property
    def output_latency_s(self) -> float:
        return 0.0


class NullSink(_PacedSink):
    """Pulls blocks at real-time pace and drops them (no sound card).

    Parameters
    ----------
    device : DeviceProfile
        Sample rate, block size and channels.
    """

    backend = "null"
    realtime = True

    def __init__(self, device: DeviceProfile) -> None:
        self.sample_rate_hz = device.sample_rate_hz
        self.block_frames = device.block_frames
        self.channels = device.channels
        self._pacer = _Pacer("phantomtouch-null-sink", device, None)

    def start(self, render: RenderFn) -> None:
        self._pacer.start(render)

    def stop(self) -> None:
        self._pacer.stop()

    def close(self) -> None:
        self._pacer.stop()


class CaptureSink(_PacedSink):
    """Records every block the engine renders.

    Parameters
    ----------
    device : DeviceProfile
    realtime : bool, default False
        False: blocks are pulled only by :meth:`pull`. True: a thread pulls them at
        real-time pace, like :class:`NullSink`.
    max_frames : int or None
        Stop recording (but keep pulling) after this many frames; None: no limit.
    wav_path : str, Path or None
        Write the recording to this float32 WAV when the sink closes.
    """

    backend = "capture"

    def __init__(
        self,
        device: DeviceProfile,
        *,
        realtime: bool = False,
        max_frames: int | None = None,
        wav_path: str | Path | None = None,
    ) -> None:
        if max_frames is not None and (isinstance(max_frames, bool) or max_frames < 0):
            raise ParameterError(f"max_frames={max_frames!r} must be None or >= 0")
        self.wav_path = None if wav_path is None else Path(wav_path)
        self.sample_rate_hz = device.sample_rate_hz
        self.block_frames = device.block_frames
        self.channels = device.channels
        self.realtime = bool(realtime)
        self.max_frames = max_frames
        self._blocks: list[np.ndarray] = []
        self._recorded = 0
        self._lock = threading.Lock()
        self._render: RenderFn | None = None
        self._buffer = np.zeros((device.block_frames, device.channels), dtype=np.float32)
        self._pacer = _Pacer("phantomtouch-capture-sink", device, self._record)

    @property
    def frames(self) -> int:
        """Frames recorded so far."""
        return self._recorded

    def start(self, render: RenderFn) -> None:
        self._render = render
        if self.realtime:
            self._pacer.start(render)

    def stop(self) -> None:
        self._pacer.stop()
        self._render = None

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
        pulled = []
        for _ in range(blocks):
            render(self._buffer)
            self._record(self._buffer)
            pulled.append(self._buffer.copy())
        if not pulled:
            return np.zeros((0, self.channels), dtype=np.float32)
        return np.concatenate(pulled)

    def _record(self, block: np.ndarray) -> None:
        keep = block.shape[0]
        if self.max_frames is not None:
            keep = max(0, min(keep, self.max_frames - self._recorded))
        if keep:
            with self._lock:
                self._blocks.append(block[:keep].copy())
                self._recorded += keep

    def recording(self) -> np.ndarray:
        """Everything recorded, shape (frames, channels), float32 (frame 0 = engine frame 0)."""
        with self._lock:
            blocks = list(self._blocks)
        if not blocks:
            return np.zeros((0, self.channels), dtype=np.float32)
        return np.concatenate(blocks)

    def write_wav(self, path: str | Path) -> Path:
        """Write the recording as a float32 WAV, one channel per output channel."""
        path = Path(path)
        soundfile.write(str(path), self.recording(), self.sample_rate_hz, subtype="FLOAT")
        return path
