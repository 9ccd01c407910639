"""The output stage: calibration per channel, FIR correction, NaN guard, safety ceiling."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch.renderer.output import OutputStage
from phantomtouch.schema import DeviceProfile


def device(**fields) -> DeviceProfile:
    return DeviceProfile.model_validate(fields)


def test_nominal_device_passes_samples_through(rng):
    block = rng.uniform(-0.9, 0.9, size=(256, 8)).astype(np.float32)
    expected = block.copy()
    OutputStage(DeviceProfile.default()).process(block)
    np.testing.assert_array_equal(block, expected)


def test_ceiling_clips_every_channel(rng):
    block = rng.uniform(-3, 3, size=(1000, 8)).astype(np.float32)
    inside = np.abs(block) <= 0.5
    expected = block.copy()
    OutputStage(device(safety={"ceiling": 0.5})).process(block)
    assert np.max(np.abs(block)) == np.float32(0.5)
    np.testing.assert_array_equal(block[inside], expected[inside])
    np.testing.assert_array_equal(block[~inside], 0.5 * np.sign(expected[~inside]))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_block_is_muted_and_counted(rng, bad):
    stage = OutputStage(DeviceProfile.default())
    block = rng.uniform(-0.5, 0.5, size=(64, 8)).astype(np.float32)
    block[10, 3] = bad
    stage.process(block)
    np.testing.assert_array_equal(block, 0.0)
    assert stage.muted_blocks == 1


def test_channel_calibration_gives_a_weaker_actuator_more_drive(rng):
    # A channel whose full-scale sine gives 6.02 dB less than the reference needs twice
    # the drive; one 6.02 dB stronger needs half.
    levels = [155.0] * 8
    levels[2] = 155.0 - 20 * np.log10(2)
    levels[5] = 155.0 + 20 * np.log10(2)
    calibrated = device(calibration={"channel_level_db": levels})
    np.testing.assert_allclose(OutputStage.channel_gains(calibrated)[[2, 5]], [2.0, 0.5])
    block = rng.uniform(-0.4, 0.4, size=(128, 8)).astype(np.float32)
    expected = block.copy()
    expected[:, 2] *= 2
    expected[:, 5] /= 2
    OutputStage(calibrated).process(block)
    np.testing.assert_allclose(block, expected, rtol=1e-6)  # float32 products


def test_fir_correction_is_continuous_across_blocks(rng):
    taps = [[0.5, 0.25, 0.125]] + [[1.0]] * 7
    calibrated = device(calibration={"fir_taps": taps})
    signal = rng.uniform(-0.5, 0.5, size=(1000, 8)).astype(np.float32)
    stage = OutputStage(calibrated)
    blocks = [signal[i : i + 97].copy() for i in range(0, 1000, 97)]
    for block in blocks:
        stage.process(block)
    out = np.concatenate(blocks)
    expected = np.convolve(signal[:, 0].astype(np.float64), taps[0])[:1000]
    # float32 storage between blocks: about 1e-7 relative.
    np.testing.assert_allclose(out[:, 0], expected, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(out[:, 1:], signal[:, 1:])
