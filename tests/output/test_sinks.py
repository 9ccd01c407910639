"""The null and capture sinks."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import soundfile

from phantomtouch import DeviceProfile, ParameterError
from phantomtouch.errors import DeviceError
from phantomtouch.output.sinks import CaptureSink, NullSink

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames


class Counter:
    """A render function that writes the frame index into channel 0."""

    def __init__(self) -> None:
        self.frames = 0

    def __call__(self, out: np.ndarray) -> None:
        out.fill(0.0)
        out[:, 0] = np.arange(self.frames, self.frames + len(out))
        self.frames += len(out)


def test_the_null_sink_pulls_blocks_at_real_time_pace() -> None:
    sink = NullSink(DEVICE)
    counter = Counter()
    began = time.monotonic()
    sink.start(counter)
    time.sleep(0.5)
    before_stop = (time.monotonic() - began) * DEVICE.sample_rate_hz
    sink.stop()  # may wait for a thread the machine keeps from running: not counted below
    after_stop = (time.monotonic() - began) * DEVICE.sample_rate_hz
    # never ahead of the clock (a block is pulled at the start of its period); behind it
    # only when the machine kept the thread from running (then counted as underruns)
    assert counter.frames <= after_stop + 2 * BLOCK
    assert counter.frames >= before_stop - 3 * BLOCK or sink.underruns > 0
    assert (sink.backend, sink.output_device, sink.output_latency_s) == ("null", None, 0.0)
    with pytest.raises(DeviceError, match="already running"):
        sink.start(counter)
        sink.start(counter)
    sink.close()


def test_the_capture_sink_records_what_it_pulled_and_writes_a_wav(tmp_path: Path) -> None:
    sink = CaptureSink(DEVICE)
    with pytest.raises(DeviceError, match="not started"):
        sink.pull(1)
    sink.start(Counter())
    pulled = sink.pull(3)
    assert pulled.shape == (3 * BLOCK, DEVICE.channels)
    np.testing.assert_array_equal(sink.recording()[:, 0], np.arange(3 * BLOCK))
    path = sink.write_wav(tmp_path / "capture.wav")
    samples, rate = soundfile.read(path, dtype="float32")
    assert rate == DEVICE.sample_rate_hz
    np.testing.assert_array_equal(samples, sink.recording())
    assert sink.pull(0).shape == (0, DEVICE.channels)


def test_the_capture_sink_stops_recording_at_max_frames() -> None:
    sink = CaptureSink(DEVICE, max_frames=300)
    sink.start(Counter())
    sink.pull(4)
    assert sink.frames == 300
    np.testing.assert_array_equal(sink.recording()[:, 0], np.arange(300))
    with pytest.raises(ParameterError, match="max_frames=-1"):
        CaptureSink(DEVICE, max_frames=-1)


def test_a_realtime_capture_sink_pulls_by_itself() -> None:
    sink = CaptureSink(DEVICE, realtime=True)
    sink.start(Counter())
    deadline = time.monotonic() + 10.0
    while sink.frames < 10 * BLOCK:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    with pytest.raises(DeviceError, match="own thread"):
        sink.pull(1)
    sink.stop()
    recording = sink.recording()
    np.testing.assert_array_equal(recording[:, 0], np.arange(len(recording)))
