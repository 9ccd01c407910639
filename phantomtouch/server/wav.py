"""A plan's render as a float32 WAV stream: header first, then blocks as they are rendered.

Nothing is written to disk and only one block is held at a time: a download that its
client abandons costs nothing once the server notices (the stream is closed, the render
slot handed back). The header is complete up front because a plan knows
its frame count: ``RIFF``/``WAVE``, a ``fmt`` chunk for IEEE float (format 3, 32 bits),
a ``fact`` chunk with the frame count, then the ``data`` chunk.
"""

from __future__ import annotations

import struct
import weakref
from collections.abc import AsyncGenerator, Callable, Iterator

import numpy as np
from starlette.concurrency import run_in_threadpool

from phantomtouch.renderer import render_plan_blocks
from phantomtouch.renderer.plan import Plan

BLOCK_FRAMES = 1 << 14
"""Frames rendered per streamed chunk (512 KiB for 8 channels)."""
_FLOAT_FORMAT = 3
_SAMPLE_BYTES = 4
HEADER_BYTES = 56
"""``RIFF`` header (12), ``fmt`` (24), ``fact`` (12) and the ``data`` chunk's header (8)."""


def wav_header(*, frames: int, channels: int, sample_rate_hz: int) -> bytes:
    """The 56-byte header of a float32 WAV of ``frames`` frames of ``channels`` channels."""
    frame_bytes = channels * _SAMPLE_BYTES
    data_bytes = frames * frame_bytes
    return b"".join(
        [
            b"RIFF",
            struct.pack("<I", HEADER_BYTES - 8 + data_bytes),
            b"WAVE",
            b"fmt ",
            struct.pack(
                "<IHHIIHH",
                16,
                _FLOAT_FORMAT,
                channels,
                sample_rate_hz,
                sample_rate_hz * frame_bytes,
                frame_bytes,
                8 * _SAMPLE_BYTES,
            ),
            b"fact",
            struct.pack("<II", 4, frames),
            b"data",
            struct.pack("<I", data_bytes),
        ]
    )


def wav_bytes(plan: Plan) -> int:
    """The length of the whole stream (``Content-Length``)."""
    return HEADER_BYTES + plan.frames * plan.channels * _SAMPLE_BYTES


def wav_stream(plan: Plan, release: Callable[[], None]) -> AsyncGenerator[bytes, None]:
    """The WAV of ``plan`` chunk by chunk; ``release()`` once when it is over.

    Each block is rendered in a worker thread. ``release`` runs when the stream is
    exhausted, closed (``aclose()``: its client gone) or dropped without ever being
    started.
    """
    once = _Once(release)
    stream = _chunks(plan, once)
    weakref.finalize(stream, once)
    return stream


class _Once:
    def __init__(self, release: Callable[[], None]) -> None:
        self._release: Callable[[], None] | None = release

    def __call__(self) -> None:
        release, self._release = self._release, None
        if release is not None:
            release()


async def _chunks(plan: Plan, release: Callable[[], None]) -> AsyncGenerator[bytes, None]:
    try:
        yield wav_header(
            frames=plan.frames, channels=plan.channels, sample_rate_hz=plan.sample_rate_hz
        )
        blocks = render_plan_blocks(plan, block_frames=BLOCK_FRAMES)
        while (chunk := await run_in_threadpool(_next_chunk, blocks)) is not None:
            yield chunk
    finally:
        release()


def _next_chunk(blocks: Iterator[np.ndarray]) -> bytes | None:
    block = next(blocks, None)
    return None if block is None else np.ascontiguousarray(block, dtype="<f4").tobytes()
