"""A snapshot of the engine for monitoring."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

from phantomtouch.schema.device import DeviceProfile

if TYPE_CHECKING:
    from phantomtouch.engine.jobs import Job
    from phantomtouch.renderer.plan import Plan
    from phantomtouch.schema.pattern import TouchPattern


class EngineFront:
    """What :class:`Engine` and its process proxy share: the device's figures, and use as
    a context manager (``start`` on entry, ``close`` on exit)."""

    _device: DeviceProfile

    def start(self) -> None:
        raise NotImplementedError

    def schedule(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
    ) -> Job:
        raise NotImplementedError

    async def schedule_async(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
    ) -> Job:
        """:meth:`schedule` for a coroutine (an engine in this process answers at once)."""
        return self.schedule(pattern, start_frame=start_frame, owner=owner)

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def device(self) -> DeviceProfile:
        return self._device

    @property
    def sample_rate_hz(self) -> int:
        return self._device.sample_rate_hz

    @property
    def block_frames(self) -> int:
        return self._device.block_frames

    @property
    def channels(self) -> int:
        return self._device.channels


@dataclass(frozen=True)
class EngineStatus:
    """A snapshot of the engine for monitoring (``/metrics``, WebSocket ``state``).

    Attributes
    ----------
    backend : {"sounddevice", "null", "capture"}
    output_device : str or None
    sample_rate_hz, block_frames, channels : int
    now_frames : int
        Frames handed to the sink so far.
    active_voices : int
        Voices rendering (jobs and contacts, releasing ones included).
    active_contacts : list of dict
        ``{"owner", "contact", "x_cm", "y_cm"}`` of every contact that is down.
    levels : list of float
        Peak absolute value per channel of the last block (after calibration, limiter).
    peak : float
        Largest absolute output sample since start.
    underruns : int
        Blocks the output needed before they were ready (sink's count).
    late_commands : int
        Commands applied after their frame had passed.
    muted_blocks : int
        Blocks replaced by silence because they carried NaN or Inf.
    limited_blocks : int
        Blocks the safety limiter turned down.
    output_latency_s : float
    queue_depth, queue_capacity : int
        Voices waiting to start, and how many may wait.
    running : bool
    render_load_p99, render_load_max : float
        p99 and largest wall time the audio callback took for a block, over the last
        4096 blocks, as a fraction of the block's playing time (1.0: the output underruns
        unless it has more buffered).
    """

    backend: str
    output_device: str | None
    sample_rate_hz: int
    block_frames: int
    channels: int
    now_frames: int
    active_voices: int
    active_contacts: list[dict[str, Any]]
    levels: list[float]
    peak: float
    underruns: int
    late_commands: int
    muted_blocks: int
    limited_blocks: int
    output_latency_s: float
    queue_depth: int
    queue_capacity: int
    running: bool
    render_load_p99: float
    render_load_max: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
