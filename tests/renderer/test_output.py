"""The output stage: calibration per channel, FIR correction, NaN guard, safety ceiling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from phantomtouch.renderer import PatternRenderer, plan
from phantomtouch.renderer.fir import PartitionedFir
from phantomtouch.renderer.output import OutputStage
from phantomtouch.renderer.presets import preset as pt_preset
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


def direct_form(taps: np.ndarray, signal: np.ndarray) -> np.ndarray:
    """The FIR in direct form, float64: y[n] = sum_k taps[k] x[n - k]."""
    return lfilter(taps, 1.0, signal.astype(np.float64))


@pytest.mark.parametrize("n_taps", [1, 3, 127, 128, 129, 1000, 4096])
def test_partitioned_fir_equals_the_direct_form(rng, n_taps):
    # Taps of a calibration filter: a decaying random response, |h|_1 about 2.
    taps = rng.standard_normal((8, n_taps)) * np.exp(-np.arange(n_taps) / (n_taps / 4 + 1))
    taps /= np.abs(taps).sum(axis=1, keepdims=True) / 2.0
    signal = rng.uniform(-1.0, 1.0, size=(20_000, 8)).astype(np.float32)
    out = signal.copy()
    fir = PartitionedFir(taps)
    for start in range(0, len(out), 1000):
        fir.process(out[start : start + 1000])
    expected = np.stack([direct_form(taps[c], signal[:, c]) for c in range(8)], axis=1)
    # The criterion, 1e-6 of full scale; float32 arithmetic throughout gives
    # about 2e-7 (outputs here reach twice full scale).
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-6)


@pytest.mark.parametrize("partition_frames", [1, 7, 32, 33, 256])
def test_partitioned_fir_equals_the_direct_form_at_any_partition_size(rng, partition_frames):
    taps = rng.standard_normal((8, 300)) * np.exp(-np.arange(300) / 60.0)
    taps /= np.abs(taps).sum(axis=1, keepdims=True)
    signal = rng.uniform(-1.0, 1.0, size=(3000, 8)).astype(np.float32)
    out = signal.copy()
    fir = PartitionedFir(taps, partition_frames=partition_frames)
    for start in range(0, len(out), 100):
        fir.process(out[start : start + 100])
    expected = np.stack([direct_form(taps[c], signal[:, c]) for c in range(8)], axis=1)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-6)


def test_partitioned_fir_block_wise_equals_whole_bit_for_bit(rng):
    taps = rng.standard_normal((8, 700)) / 30.0
    signal = rng.uniform(-1.0, 1.0, size=(6000, 8)).astype(np.float32)
    whole = signal.copy()
    PartitionedFir(taps).process(whole)
    for sizes in ([1] * 300 + [5700], [16, 127, 128, 129, 1000, 4600], [333] * 18 + [6]):
        fir, out, start = PartitionedFir(taps), signal.copy(), 0
        for size in sizes:
            fir.process(out[start : start + size])
            start += size
        assert start == len(signal)
        np.testing.assert_array_equal(out.view(np.uint32), whole.view(np.uint32))


def test_identity_taps_pass_samples_through_exactly(rng):
    signal = rng.uniform(-1.0, 1.0, size=(1000, 8)).astype(np.float32)
    out = signal.copy()
    PartitionedFir([[1.0]] * 8).process(out)
    np.testing.assert_array_equal(out, signal)


def test_non_finite_input_does_not_poison_the_fir(rng):
    taps = [[0.5, 0.25, 0.125] * 100] + [[1.0]] * 7
    stage = OutputStage(device(calibration={"fir_taps": taps}))
    bad = rng.uniform(-0.1, 0.1, size=(256, 8)).astype(np.float32)
    bad[10, 0] = np.nan
    stage.process(bad)
    assert stage.muted_blocks == 1
    good = rng.uniform(-0.1, 0.1, size=(256, 8)).astype(np.float32)
    stage.process(good)
    assert np.all(np.isfinite(good)) and np.any(good != 0.0)


@pytest.mark.parametrize(
    "preset", ["exp2/central", "exp1/sine100-high-v10-am", "exp1/noise-high-v3"]
)
def test_a_renderers_peak_bound_holds_and_its_blocks_come_out_as_a_full_look_gives(preset):
    """The offline render skips the stage's look at a block its renderer's bound proves
    finite and within the ceiling: every block is within the bound, and comes out as the
    stage gives it without one."""
    resolved = plan(pt_preset(preset), DeviceProfile.default())
    renderer = PatternRenderer(resolved)
    bounded, looked = OutputStage(resolved.device), OutputStage(resolved.device)
    while not renderer.finished:
        block = renderer.render(4096)
        assert np.abs(block).max() <= renderer.peak_bound
        reference = block.copy()
        bounded.process(block, renderer.peak_bound)
        looked.process(reference)
        np.testing.assert_array_equal(block, reference)


@pytest.mark.parametrize("bound", [np.nan, 2.0])
def test_a_bound_that_proves_nothing_leaves_the_stage_its_look(rng, bound):
    """A NaN bound (a carrier or gain not finite) or one past the ceiling: the stage still
    mutes what is not finite and clips what is too loud."""
    stage = OutputStage(device(safety={"ceiling": 0.5}))
    loud = rng.uniform(-3, 3, size=(64, 8)).astype(np.float32)
    stage.process(loud, bound)
    assert np.max(np.abs(loud)) == np.float32(0.5)
    bad = rng.uniform(-0.4, 0.4, size=(64, 8)).astype(np.float32)
    bad[5, 2] = np.nan
    stage.process(bad, bound)
    np.testing.assert_array_equal(bad, 0.0)
