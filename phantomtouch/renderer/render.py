"""Offline rendering: a whole pattern, or the same samples block by block."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from phantomtouch.errors import ParameterError
from phantomtouch.renderer.output import OutputStage
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.renderer.voice import PatternRenderer
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import TouchPattern

_WHOLE_RENDER_BLOCK_FRAMES = 1 << 16


def _device_at(device: DeviceProfile | None, sample_rate_hz: int | None) -> DeviceProfile:
    device = device or DeviceProfile.default()
    if sample_rate_hz is None or sample_rate_hz == device.sample_rate_hz:
        return device
    if not limits.MIN_SAMPLE_RATE_HZ <= sample_rate_hz <= limits.MAX_SAMPLE_RATE_HZ:
        raise ParameterError(
            f"sample_rate_hz={sample_rate_hz!r} must be within "
            f"[{limits.MIN_SAMPLE_RATE_HZ}, {limits.MAX_SAMPLE_RATE_HZ}]"
        )
    return device.model_copy(update={"sample_rate_hz": int(sample_rate_hz)})


def plan_at(
    pattern: TouchPattern, device: DeviceProfile | None = None, *, sample_rate_hz: int | None = None
) -> Plan:
    """:func:`plan` for ``device`` at another sample rate (None: the device's own)."""
    return plan(pattern, _device_at(device, sample_rate_hz))


def render_plan_blocks(resolved: Plan, *, block_frames: int = 1024) -> Iterator[np.ndarray]:
    """Blocks of a plan's output, calibrated and limited like the engine's output."""
    if block_frames < 1:
        raise ParameterError(f"block_frames={block_frames!r} must be >= 1")
    voice = PatternRenderer(resolved)
    stage = OutputStage(resolved.device)
    while not voice.finished:
        block = voice.render(min(block_frames, voice.remaining_frames))
        stage.process(block, voice.peak_bound)
        yield block


def render_blocks(
    pattern: TouchPattern,
    device: DeviceProfile | None = None,
    *,
    sample_rate_hz: int | None = None,
    block_frames: int = 1024,
) -> Iterator[np.ndarray]:
    """Render a pattern block by block; memory stays bounded by ``block_frames``.

    Parameters
    ----------
    pattern : TouchPattern
    device : DeviceProfile or None
        None: the paper's armband.
    sample_rate_hz : int or None
        None: the device's rate (48000 for the default device).
    block_frames : int, >= 1

    Yields
    ------
    ndarray, shape (block_frames, channels), float32
        The last block may be shorter. The blocks concatenate to exactly :func:`render`.
    """
    resolved = plan_at(pattern, device, sample_rate_hz=sample_rate_hz)
    return render_plan_blocks(resolved, block_frames=block_frames)


def render(
    pattern: TouchPattern,
    device: DeviceProfile | None = None,
    *,
    sample_rate_hz: int | None = None,
) -> np.ndarray:
    """Render a whole pattern to the 8 (or the device's) actuator signals.

    Returns
    -------
    ndarray, shape (frames, channels), float32
        Within the device's ceiling, finite.
    """
    resolved = plan_at(pattern, device, sample_rate_hz=sample_rate_hz)
    out = np.empty((resolved.frames, resolved.channels), dtype=np.float32)
    voice = PatternRenderer(resolved)
    stage = OutputStage(resolved.device)
    start = 0
    while not voice.finished:
        block = out[start : start + _WHOLE_RENDER_BLOCK_FRAMES]
        voice.render_into(block)
        stage.process(block, voice.peak_bound)
        start += len(block)
    return out
