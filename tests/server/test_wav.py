"""The streamed WAV: a header libsndfile reads, the samples of the offline render."""

from __future__ import annotations

import asyncio
import contextlib
import io
from collections.abc import AsyncIterator

import numpy as np
import soundfile

from phantomtouch import preset, render
from phantomtouch.renderer import plan
from phantomtouch.server.wav import HEADER_BYTES, wav_bytes, wav_header, wav_stream


def test_header_is_what_libsndfile_reads() -> None:
    header = wav_header(frames=0, channels=8, sample_rate_hz=48_000)
    assert len(header) == HEADER_BYTES
    info = soundfile.info(io.BytesIO(header))
    assert (info.channels, info.samplerate, info.frames, info.subtype) == (8, 48_000, 0, "FLOAT")


async def collect(stream: AsyncIterator[bytes]) -> bytes:
    return b"".join([chunk async for chunk in stream])


def test_the_stream_is_the_offline_render_and_releases_its_slot() -> None:
    planned = plan(preset("vr/tap"))
    released: list[int] = []
    data = asyncio.run(collect(wav_stream(planned, lambda: released.append(1))))
    assert len(data) == wav_bytes(planned)
    samples, rate_hz = soundfile.read(io.BytesIO(data), dtype="float32")
    assert rate_hz == planned.sample_rate_hz
    np.testing.assert_array_equal(samples, render(preset("vr/tap")))  # same code, same bits
    assert released == [1]


def test_a_stream_abandoned_early_or_never_started_releases_its_slot() -> None:
    planned = plan(preset("exp2/curved"))
    released: list[str] = []

    async def abandon() -> None:
        stream = wav_stream(planned, lambda: released.append("cancelled"))

        async def download() -> None:
            async for _ in stream:
                await asyncio.sleep(10)  # a client that stopped reading

        task = asyncio.create_task(download())
        await asyncio.sleep(0.1)
        task.cancel()  # what the server does when the client leaves ...
        with contextlib.suppress(asyncio.CancelledError):
            await task
        await stream.aclose()  # ... and then, in the response's background task
        assert released == ["cancelled"], "at once, not when collected"

    asyncio.run(abandon())
    wav_stream(planned, lambda: released.append("never"))  # dropped at once
    assert released == ["cancelled", "never"]
