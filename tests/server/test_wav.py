"""The streamed WAV: a header libsndfile reads, the samples of the offline render."""

from __future__ import annotations

import io

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


def test_the_stream_is_the_offline_render_and_releases_its_slot() -> None:
    planned = plan(preset("vr/tap"))
    released: list[int] = []
    data = b"".join(wav_stream(planned, lambda: released.append(1)))
    assert len(data) == wav_bytes(planned)
    samples, rate_hz = soundfile.read(io.BytesIO(data), dtype="float32")
    assert rate_hz == planned.sample_rate_hz
    np.testing.assert_array_equal(samples, render(preset("vr/tap")))  # same code, same bits
    assert released == [1]


def test_a_stream_abandoned_early_or_never_started_releases_its_slot() -> None:
    planned = plan(preset("exp2/curved"))
    released: list[str] = []
    started = wav_stream(planned, lambda: released.append("started"))
    next(started)
    started.close()  # what the server does when the client leaves
    wav_stream(planned, lambda: released.append("never"))  # dropped at once
    assert sorted(released) == ["never", "started"]
