"""A snapshot of the engine for monitoring."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class EngineStatus:
    """A snapshot of the engine for monitoring (``/metrics``, WebSocket ``state``).

    Attributes
    ----------
    backend, output_device, sample_rate_hz, block_frames, channels
        The sink's (``"sounddevice"``, ``"null"`` or ``"capture"``; the sound card output
        or None) and the device's.
    now_frames : int
        Frames handed to the sink so far.
    active_voices, active_contacts
        Voices rendering (releasing ones included); ``{"owner", "contact", "x_cm",
        "y_cm"}`` of every contact that is down.
    levels, peak
        Peak absolute value per channel of the last block (after calibration, limiter),
        and the largest output sample since start.
    underruns, late_commands, muted_blocks, limited_blocks, callback_errors : int
        Blocks the output needed before they were ready (the sink's count); commands
        applied after their frame had passed; blocks muted for NaN or Inf, turned down by
        the limiter, replaced by silence because rendering raised.
    queue_depth, queue_capacity : int
        Voices waiting to start, and how many may wait.
    period_frames : int
        Frames of each callback: the sound card's period (``block_frames`` is it or a
        fixed divisor of it).
    period_source : str
        Where the period came from: ``"backend"`` (the audio server's or the host API's
        buffer), ``"option"`` (``--period``) or ``"profile"`` (the profile's
        ``block_frames``: an output without a period of its own).
    render_load_p99, render_load_max : float
        p99 and largest time the callback took over the last 4096 callbacks, as a share
        of the time it had: its period's playing time (1.0: the output underruns).
    callback_p50_s, callback_p99_s, callback_max_s : float
        The callback's own time over the same callbacks, s: median, p99 and largest.
    state, running, restarts
        ``"running"``, ``"starting"``, ``"stalled"`` or ``"gone"`` (until a restart),
        ``"restarting"`` (a new engine process is opening its sink), ``"closed"``; times
        the engine process was restarted after it died or stalled.
    voice_capacity, voice_cost, start_cost, starts_per_block, render_budget
        Admission by budget (``docs/engine.md``): pattern voices admitted at once, the
        measured load of one and what one adds to the block it begins in, starts per
        block, and the share of a block voices may take.
    refused_commands : int
        Commands refused for data (a plan, a noise loop) not handed over: a host bug.
    output_latency_s : float
        Time from a block's computation to its first frame leaving the sound card, s.
    inline_renders : int
        Times the audio callback rendered into a voice's ring that ran dry (the
        render-ahead thread fell behind).
    nonfinite_voices, overrun_voices : int
        Voices silenced alone while the others played on: for samples that were not
        finite, and for running past their render budget block after block.
    dc_blocked_blocks : int
        Blocks the DC blocker changed (``renderer/dc_blocker.py``).
    """

    backend: str
    output_device: str | None
    sample_rate_hz: int
    block_frames: int
    period_frames: int
    period_source: str
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
    callback_p50_s: float
    callback_p99_s: float
    callback_max_s: float
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
    nonfinite_voices: int = 0
    overrun_voices: int = 0
    dc_blocked_blocks: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
