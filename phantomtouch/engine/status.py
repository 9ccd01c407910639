"""A snapshot of the engine for monitoring."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


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
    state : {"running", "starting", "stalled", "gone", "closed"}
        Whether audio flows: ``stalled`` (the engine process stopped calling back) and
        ``gone`` (it died) last until it is restarted.
    voice_capacity : int
        Pattern voices admitted at once: ``render_budget`` over ``voice_cost``, at most
        ``max_voices``.
    voice_cost : float
        Measured render load of one pattern voice, a fraction of a block's playing time.
    start_cost : float
        What a voice adds to the block it begins in, a fraction of its playing time.
    starts_per_block : int
        Pattern voices that may begin in one block.
    render_budget : float
    callback_errors : int
        Blocks replaced by silence because rendering raised.
    restarts : int
        Times the engine process was restarted after it died or stalled.
    refused_commands : int
        Commands the audio side refused because their data (a plan, a noise loop) was
        not handed to it; 0 unless the host has a bug: the audio side never builds them.
    inline_renders : int
        Times the audio callback rendered into a voice's ring that ran dry (the
        render-ahead thread fell behind).
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
    state: str
    voice_capacity: int
    voice_cost: float
    start_cost: float
    starts_per_block: int
    render_budget: float
    callback_errors: int
    restarts: int
    refused_commands: int = 0
    inline_renders: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
