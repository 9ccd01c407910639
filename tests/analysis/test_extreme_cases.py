"""Stiff and extreme input: the renderer stays finite and within the ceiling, and gives
either the right result or an error that names the field."""

import json
import math
import tracemalloc
from fractions import Fraction
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError
from scipy import signal

from phantomtouch import (
    DeviceError,
    DeviceProfile,
    ParameterError,
    TouchPattern,
    gains_at,
    plan,
    render,
    render_blocks,
)
from phantomtouch.analysis.accuracy import TWO_POINT_THRESHOLD_CM, effective_gains, gain_centroid
from phantomtouch.analysis.twin import ActuatorModel, euler_accelerations
from phantomtouch.renderer.carriers import NOISE_PERIOD_FRAMES, NoiseSource
from phantomtouch.renderer.gains import apply_law
from phantomtouch.renderer.trajectory import envelope_at, positions_at
from phantomtouch.schema import limits

DEVICE = DeviceProfile.default()
RATE = DEVICE.sample_rate_hz


def pattern(**fields: Any) -> TouchPattern:
    data = {"carrier": {"kind": "sine", "freq_hz": 100.0}, "intensity": "low", **fields}
    return TouchPattern.model_validate(data)


def still(x_cm: float = 1.0, y_cm: float = 1.0, **fields: Any) -> TouchPattern:
    return pattern(path={"kind": "polyline", "points_cm": [[x_cm, y_cm]]}, **fields)


def assert_sane(out: np.ndarray, device: DeviceProfile = DEVICE) -> None:
    assert out.dtype == np.float32 and out.shape[1] == device.channels
    assert np.all(np.isfinite(out))
    assert np.max(np.abs(out), initial=0.0) <= device.safety.ceiling


# --- speeds -------------------------------------------------------------------------


@pytest.mark.parametrize("speed_cm_s", [0.01, 0.1, 1.0, 10.0, 100.0, 1000.0])
def test_every_speed_from_0_01_to_1000_cm_s_follows_the_path(speed_cm_s: float) -> None:
    length = min(14.0, speed_cm_s * 0.5)  # half a second of motion, at most the band
    stroke = pattern(
        path={"kind": "polyline", "points_cm": [[1.0, 0.2], [1.0, 0.2 + length]]},
        speed_cm_s=speed_cm_s,
        fade_in_s=0.05,
        fade_out_s=0.05,
    )
    resolved = plan(stroke)
    assert resolved.duration_s == pytest.approx(0.1 + length / speed_cm_s, rel=1e-12)  # eq. 1
    assert resolved.frames == round(resolved.duration_s * RATE)
    assert_sane(render(stroke))
    times = np.arange(resolved.frames) / RATE
    points, _ = positions_at(resolved, times)
    sounding = envelope_at(resolved, times) > 0
    centroid = gain_centroid(effective_gains(resolved), resolved.geometry)
    error = np.hypot(*(centroid - points)[sounding].T)
    # never further from the path than the point moves between two gain updates
    step_cm = speed_cm_s * DEVICE.gain_step_frames / RATE
    assert np.max(error) <= step_cm + 1e-5  # 1e-5 cm: float32 gains
    assert np.max(error) < TWO_POINT_THRESHOLD_CM


def test_speed_above_the_cap_is_refused_by_name() -> None:
    with pytest.raises(ValidationError, match="speed_cm_s"):
        pattern(path={"kind": "polyline", "points_cm": [[0, 0], [0, 14]]}, speed_cm_s=1000.001)
    with pytest.raises(ValidationError, match="speed_cm_s"):
        pattern(path={"kind": "polyline", "points_cm": [[0, 0], [0, 14]]}, speed_cm_s=0.0)
    too_short = pattern(
        path={"kind": "polyline", "points_cm": [[0, 0], [0, 14]]}, duration_s=1.21, repeat=1
    )
    with pytest.raises(ParameterError, match=r"duration_s=1\.21"):
        plan(too_short)  # 14 cm in 0.01 s: 1400 cm/s
    jump = [{"t_s": 0.0, "x_cm": 0.0, "y_cm": 0.0}, {"t_s": 0.001, "x_cm": 0.0, "y_cm": 14.0}]
    with pytest.raises(ParameterError, match=r"keyframes\[1\]"):
        plan(pattern(path={"kind": "keyframes", "keyframes": jump}))


def test_a_speed_that_needs_more_than_the_duration_cap_is_refused() -> None:
    slow = pattern(path={"kind": "polyline", "points_cm": [[0, 0], [0, 14.4]]}, speed_cm_s=0.001)
    with pytest.raises(ParameterError, match="at most 7200 s"):
        plan(slow)


# --- zero-length paths and repeated points ---------------------------------------------


@pytest.mark.parametrize(
    "path",
    [
        {"kind": "polyline", "points_cm": [[1.2, 3.4]]},
        {"kind": "polyline", "points_cm": [[1.2, 3.4], [1.2, 3.4]]},
        {"kind": "spline", "points_cm": [[1.2, 3.4], [1.2, 3.4], [1.2, 3.4]]},
        {"kind": "arc", "start_cm": [1.2, 3.4], "through_cm": [1.2, 3.4], "end_cm": [1.2, 3.4]},
        {"kind": "keyframes", "keyframes": [{"t_s": 0.5, "x_cm": 1.2, "y_cm": 3.4}]},
    ],
)
def test_zero_length_paths_touch_one_point(path: dict[str, Any]) -> None:
    timing = {} if path["kind"] == "keyframes" else {"speed_cm_s": 5.0}
    touch = pattern(path=path, **timing)
    resolved = plan(touch)
    assert resolved.path_length_cm == 0.0 and resolved.speed_cm_s == 0.0
    expected_s = 1.2 + (0.5 if path["kind"] == "keyframes" else 0.0)
    assert resolved.duration_s == pytest.approx(expected_s)
    out = render(touch)
    assert_sane(out)
    sounding = np.any(out != 0, axis=1)
    centroid = gain_centroid(effective_gains(resolved), resolved.geometry)[sounding]
    np.testing.assert_allclose(centroid, np.broadcast_to([1.2, 3.4], centroid.shape), atol=1e-5)


def test_zero_length_without_any_duration_is_refused() -> None:
    with pytest.raises(ParameterError, match="zero duration"):
        plan(still(speed_cm_s=1.0, fade_in_s=0.0, fade_out_s=0.0))
    with pytest.raises(ParameterError, match=r"duration_s=1\.0"):
        plan(still(duration_s=1.0))  # shorter than the two 0.6 s fades


@pytest.mark.parametrize("kind", ["polyline", "spline"])
def test_repeated_points_change_nothing(kind: str) -> None:
    points = [[0.5, 1.0], [1.5, 5.0], [3.0, 9.0], [2.0, 13.0]]
    repeated = [points[0], points[0], points[1], points[1], points[1], points[2], points[3]]
    plain = render(pattern(path={"kind": kind, "points_cm": points}, speed_cm_s=7.0))
    doubled = render(pattern(path={"kind": kind, "points_cm": repeated}, speed_cm_s=7.0))
    np.testing.assert_array_equal(doubled, plain)


# --- vertices, edges, outside the hull -------------------------------------------------

LAW_AT_HALF = {"power": math.sqrt(0.5), "log": math.log2(1.5), "linear": 0.5}


@pytest.mark.parametrize("law", ["power", "log", "linear"])
def test_on_a_vertex_only_its_actuator_vibrates(law: str) -> None:
    for actuator in DEVICE.actuators:
        gains = gains_at(DEVICE, actuator.x_cm, actuator.y_cm, law=law)
        expected = np.zeros(8)
        expected[actuator.channel - 1] = 1.0
        np.testing.assert_array_equal(gains, expected)


@pytest.mark.parametrize("law", ["power", "log", "linear"])
def test_mid_edge_gives_the_law_at_one_half(law: str) -> None:
    # along the band (x = 0: channels 1, 2), around it (y = 0: 1, 5), the diagonal (1, 6)
    for x, y, pair in ((0.0, 2.4, (0, 1)), (1.9, 0.0, (0, 4)), (1.9, 2.4, (0, 5))):
        gains = gains_at(DEVICE, x, y, law=law)
        assert gains[list(pair)] == pytest.approx([LAW_AT_HALF[law]] * 2, rel=1e-12)
        assert np.count_nonzero(gains) == 2


def test_outside_points_get_the_gains_of_their_projection(rng: np.random.Generator) -> None:
    # the default layout's hull is the rectangle [0, 3.8] x [0, 14.4]
    for x, y in rng.uniform(-1000.0, 1000.0, size=(50, 2)):
        projected = gains_at(DEVICE, float(np.clip(x, 0, 3.8)), float(np.clip(y, 0, 14.4)))
        np.testing.assert_allclose(gains_at(DEVICE, x, y), projected, atol=1e-12)
    with pytest.raises(ParameterError, match="x_cm=1e"):
        gains_at(DEVICE, 1e300, 0.0)


def test_outside_path_points_are_projected_or_refused_by_index() -> None:
    path = {"kind": "polyline", "points_cm": [[1.0, 1.0], [-3.0, 20.0], [2.0, 2.0]]}
    projected = plan(pattern(path=path, speed_cm_s=50.0))
    assert projected.projected_points == 1
    assert projected.max_projection_cm == pytest.approx(math.hypot(3.0, 5.6))
    assert_sane(render(pattern(path=path, speed_cm_s=50.0)))
    with pytest.raises(ParameterError, match=r"path point 1 at \(-3, 20\)"):
        plan(pattern(path=path, speed_cm_s=50.0, outside="error"))


# --- huge paths and a one-hour pattern -------------------------------------------------


@pytest.mark.parametrize("kind", ["polyline", "spline", "keyframes"])
def test_paths_of_100000_points(kind: str) -> None:
    n = limits.MAX_PATH_POINTS
    t = np.linspace(0.0, 1.0, n)
    points = np.stack([1.9 + 1.8 * np.sin(2 * np.pi * 40 * t), 0.2 + 14.0 * t], axis=1)
    if kind == "keyframes":
        frames = [
            {"t_s": 2.0 * s, "x_cm": x, "y_cm": y} for s, (x, y) in zip(t, points, strict=True)
        ]
        path: dict[str, Any] = {"kind": kind, "keyframes": frames}
        touch = pattern(path=path)
    else:
        path = {"kind": kind, "points_cm": points.tolist()}
        touch = pattern(path=path, speed_cm_s=1000.0)
    resolved = plan(touch)
    if kind != "spline":  # a polyline's length is the sum of its segments
        expected = float(np.sum(np.hypot(*np.diff(points, axis=0).T)))
        assert resolved.path_length_cm == pytest.approx(expected, rel=1e-12)
    assert_sane(render(touch))
    too_many = {**path}
    key = "keyframes" if kind == "keyframes" else "points_cm"
    too_many[key] = [*path[key], path[key][-1]]
    with pytest.raises(ValidationError, match=key):
        pattern(path=too_many, **({} if kind == "keyframes" else {"speed_cm_s": 1.0}))


def _peak_memory(touch: TouchPattern) -> tuple[int, np.ndarray, int]:
    """Render block-wise; peak traced memory, the frames around t = 3600 s, frames."""
    tracemalloc.start()
    target, kept, frames = 3600 * RATE, np.zeros(0, np.float32), 0
    for block in render_blocks(touch, block_frames=1 << 15):
        assert_sane(block)
        if frames <= target < frames + len(block):
            kept = block[target - frames : target - frames + 1000, 0].copy()
        frames += len(block)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak, kept, frames


@pytest.mark.slow
def test_one_hour_renders_in_bounded_memory_without_phase_drift() -> None:
    freq = "97.3"  # no whole number of periods per second: the phase never repeats exactly
    hour = still(0.0, 0.0, duration_s=3601.0, carrier={"kind": "sine", "freq_hz": float(freq)})
    peak_hour, kept, frames = _peak_memory(hour)
    peak_short, _, _ = _peak_memory(still(0.0, 0.0, duration_s=10.0))
    assert frames == 3601 * RATE
    # the whole hour would be 5.5 GB of float32; block-wise it needs what 10 s need
    assert peak_hour < 2 * peak_short + (1 << 20)
    amplitude = plan(hour).amplitude
    exact = []
    for n in range(3600 * RATE, 3600 * RATE + len(kept)):
        cycles = Fraction(freq) * n / RATE  # exact rational phase, in cycles
        exact.append(math.sin(2 * math.pi * float(cycles - math.floor(cycles))))
    # float32 carrier: 2e-6 of the amplitude; a float32 time axis would be off by O(1)
    np.testing.assert_allclose(kept / amplitude, exact, rtol=0, atol=2e-6)


# --- modulation ------------------------------------------------------------------------


def test_modulation_index_zero_is_no_modulation() -> None:
    path = {"kind": "polyline", "points_cm": [[0.5, 1.0], [3.0, 12.0]]}
    plain = render(pattern(path=path, speed_cm_s=10.0))
    zero = render(pattern(path=path, speed_cm_s=10.0, modulation={"index": 0.0}))
    np.testing.assert_array_equal(zero, plain)


@pytest.mark.parametrize("freq_hz", ["stroke", 1000.0])
def test_modulation_index_one_follows_eq_2(freq_hz: Any) -> None:
    path = {"kind": "polyline", "points_cm": [[0.5, 1.0], [3.0, 12.0]]}
    touch = pattern(path=path, speed_cm_s=10.0, modulation={"index": 1.0, "freq_hz": freq_hz})
    resolved = plan(touch)
    t = np.linspace(0.0, resolved.duration_s, 5001, endpoint=False)
    fades = np.clip(t / 0.6, 0, 1) * np.clip((resolved.duration_s - t) / 0.6, 0, 1)
    cycles = t / resolved.duration_s if freq_hz == "stroke" else t * freq_hz
    expected = fades * (0.5 - 0.5 * np.cos(2 * np.pi * cycles))  # eq. 2 with m = 1
    np.testing.assert_allclose(envelope_at(resolved, t), expected, atol=1e-12)
    assert_sane(render(touch))


# --- noise near 0 Hz and near Nyquist ------------------------------------------------


@pytest.mark.parametrize(("low_hz", "high_hz"), [(1.0, 40.0), (20.0, 21.0), (40.0, 42.0)])
def test_low_and_narrow_noise_is_at_full_level_from_the_first_frame(
    low_hz: float, high_hz: float
) -> None:
    # over many seeds the power of the first 0.25 s is the steady power 1/2: the noise
    # neither fades in nor overshoots (40 seeds: the mean is within ±50 % at 3 sigma)
    first = [
        np.mean(NoiseSource(low_hz, high_hz, seed, RATE).block(0, RATE // 4).astype(float) ** 2)
        for seed in range(40)
    ]
    assert np.mean(first) == pytest.approx(0.5, rel=0.5)


def test_noise_near_nyquist_has_its_rms() -> None:
    band = {"kind": "noise", "low_hz": 20000.0, "high_hz": 21600.0}
    touch = still(0.0, 0.0, duration_s=2.0, carrier=band, intensity=0.5)  # channel 1 only
    out = render(touch, sample_rate_hz=RATE)
    assert_sane(out)
    amplitude = plan(touch).amplitude
    steady = out[round(0.6 * RATE) : -round(0.6 * RATE)].astype(float)
    # unit-amplitude carriers have the RMS of a unit sine; 0.6 s of 1.6 kHz-wide noise
    rms = np.sqrt(np.mean(steady[:, 0] ** 2))
    assert rms == pytest.approx(amplitude / math.sqrt(2), rel=0.03)


@pytest.mark.parametrize(
    ("carrier", "error", "field"),
    [
        ({"kind": "noise", "low_hz": 20000.0, "high_hz": 21601.0}, ParameterError, "high_hz"),
        ({"kind": "noise", "low_hz": 21000.0, "high_hz": 21600.0}, ValidationError, "high_hz"),
        ({"kind": "noise", "low_hz": 0.5, "high_hz": 40.0}, ValidationError, "low_hz"),
        ({"kind": "noise", "low_hz": 10.0, "high_hz": 10.6}, ParameterError, "too narrow"),
        ({"kind": "combined", "low_hz": 1.0, "high_hz": 1.06}, ParameterError, "low_hz=1.0"),
        ({"kind": "sine", "freq_hz": 24000.0}, ParameterError, "freq_hz=24000"),
    ],
)
def test_bands_that_cannot_work_are_refused_by_name(
    carrier: dict[str, Any], error: type[Exception], field: str
) -> None:
    with pytest.raises(error, match=field):
        plan(still(duration_s=2.0, carrier=carrier))


def test_the_narrowest_noise_band_spans_the_loops_minimum_of_frequency_steps() -> None:
    narrowest_hz = limits.MIN_NOISE_LOOP_BINS * RATE / NOISE_PERIOD_FRAMES  # 0.73 Hz
    wide_enough = {"kind": "noise", "low_hz": 1.0, "high_hz": 1.0 + 1.001 * narrowest_hz}
    assert_sane(render(still(duration_s=2.0, carrier=wide_enough)))
    too_narrow = {"kind": "noise", "low_hz": 1.0, "high_hz": 1.0 + 0.999 * narrowest_hz}
    with pytest.raises(ParameterError, match="too narrow"):
        plan(still(duration_s=2.0, carrier=too_narrow))


# --- the log law at zero weight --------------------------------------------------------


def test_log_law_at_zero_weight_is_silent_not_minus_infinity() -> None:
    weights = np.array([0.0, 1e-300, 5e-324, 0.5, 1.0])
    gains = apply_law(weights, "log")
    assert np.all(np.isfinite(gains)) and gains[0] == 0.0 and gains[-1] == 1.0
    # docs/algorithms.md sec. 4: -1.65 dB of energy mid-edge, -2.87 dB at a triangle's centroid
    mid_edge = gains_at(DEVICE, 0.0, 2.4, law="log")
    assert 10 * np.log10(np.sum(mid_edge**2)) == pytest.approx(-1.65, abs=0.01)
    centroid = gains_at(DEVICE, 3.8 * 2 / 3, 4.8 / 3, law="log")  # triangle (1, 5, 6)
    assert 10 * np.log10(np.sum(centroid**2)) == pytest.approx(-2.87, abs=0.01)
    through_vertices = pattern(
        path={"kind": "polyline", "points_cm": [[0, 0], [3.8, 4.8], [0, 9.6], [3.8, 14.4]]},
        speed_cm_s=20.0,
        law="log",
    )
    assert_sane(render(through_vertices))


# --- degenerate and near-degenerate layouts -------------------------------------------


def layout(points: list[tuple[float, float]], **fields: Any) -> dict[str, Any]:
    actuators = [{"x_cm": x, "y_cm": y, "channel": k + 1} for k, (x, y) in enumerate(points)]
    return {"actuators": actuators, **fields}


@pytest.mark.parametrize(
    ("points", "message"),
    [
        ([(0, 0), (1, 0), (2, 0)], "collinear"),
        ([(0, 0), (1, 1e-9), (2, 0), (3, -1e-9)], "collinear"),
        ([(0, 0), (0, 0.05), (2, 0), (0, 2)], "duplicate actuators"),
    ],
)
def test_degenerate_layouts_are_refused(points: list, message: str, tmp_path) -> None:
    with pytest.raises(ValidationError, match=message):
        DeviceProfile.model_validate(layout(points))
    path = tmp_path / "layout.json"
    path.write_text(json.dumps(layout(points)), encoding="utf-8")
    with pytest.raises(DeviceError, match=message):
        DeviceProfile.load(path)


def test_a_zero_area_triangle_is_refused_by_index() -> None:
    with pytest.raises(ValidationError, match=r"triangles\[0\]"):
        DeviceProfile.model_validate(
            layout([(0, 0), (1, 0), (2, 0), (1, 2)], triangles=[[0, 1, 2], [0, 2, 3]])
        )


@pytest.mark.parametrize("offset_cm", [1e-3, 1e-6, 1e-9])
def test_near_degenerate_layouts_render_the_right_gains(offset_cm: float) -> None:
    # three actuators almost on a line (a sliver triangle between them) and one above
    device = DeviceProfile.model_validate(layout([(0, 0), (2, 0), (1, offset_cm), (1, 3)]))
    # halfway between (0, 0) and (2, 0): the power law puts sqrt(1/2) on both
    gains = gains_at(device, 1.0, 0.0)
    assert gains[:2] == pytest.approx([math.sqrt(0.5)] * 2, abs=1e-6)
    np.testing.assert_allclose(gains_at(device, 1.0, offset_cm), [0, 0, 1, 0], atol=1e-6)
    path = [[0.0, 0.0], [2.0, 0.0], [1.0, offset_cm / 2], [1.0, 3.0]]
    out = render(pattern(path={"kind": "polyline", "points_cm": path}, speed_cm_s=10.0), device)
    assert_sane(out, device)


def test_a_sliver_below_numerical_resolution_is_dropped() -> None:
    # a triangle of 1e-10 cm² covers nothing: its three actuators belong to the others,
    # and (1, 1e-10) acts as a point of the hull's lower edge
    device = DeviceProfile.model_validate(layout([(0, 0), (2, 0), (1, 1e-10), (1, 3)]))
    np.testing.assert_allclose(gains_at(device, 1.0, 0.0), [0, 0, 1, 0], atol=1e-9)
    half = math.sqrt(0.5)
    np.testing.assert_allclose(gains_at(device, 0.5, 0.0), [half, 0, half, 0], atol=1e-9)
    assert_sane(render(still(1.0, 0.0, duration_s=2.0), device), device)


# --- the ceiling -------------------------------------------------------------------------


def test_calibration_boost_never_exceeds_the_ceiling() -> None:
    weak = DeviceProfile.model_validate(
        {
            "calibration": {"channel_level_db": [100.0] + [155.0] * 7},  # +55 dB on channel 1
            "safety": {"ceiling": 0.5},
        }
    )
    out = render(still(0.0, 0.0, duration_s=2.0, intensity=1.0), weak)
    assert_sane(out, weak)
    assert np.max(np.abs(out[:, 0])) == np.float32(0.5)  # clipped, not wrapped or NaN


# --- the twin at stiff parameters ----------------------------------------------------------

RATES_HZ = (8000, 48000, 192000)


@pytest.mark.parametrize("rate_hz", RATES_HZ)
def test_bilinear_twin_is_stable_for_q_up_to_1000_and_resonance_near_nyquist(
    rate_hz: int,
) -> None:
    for f0 in (1.0, 170.0, 0.25 * rate_hz, 0.45 * rate_hz, 0.499 * rate_hz):
        for q in (0.1, 0.5, 0.7071, 2.0, 5.0, 50.0, 1000.0):
            assert np.max(np.abs(ActuatorModel(f0_hz=f0, q=q).poles_z(rate_hz))) < 1.0


@pytest.mark.parametrize(("f0_fraction", "q"), [(0.49, 3.0), (0.49, 1000.0), (170 / 48000, 1000.0)])
def test_euler_twin_explodes_where_the_bilinear_twin_is_bounded(
    f0_fraction: float, q: float, rng: np.random.Generator
) -> None:
    model = ActuatorModel(f0_hz=f0_fraction * RATE, q=q)
    drive = rng.standard_normal(RATE)
    stable = signal.sosfilt(model.sos(RATE), drive)
    # Parseval: output RMS <= max |H| x input RMS (white noise; 5 % for the finite length)
    _, h = signal.sosfreqz(model.sos(RATE), worN=1 << 16, fs=RATE)
    assert np.all(np.isfinite(stable))
    assert np.sqrt(np.mean(stable**2)) <= 1.05 * np.max(np.abs(h)) * np.sqrt(np.mean(drive**2))
    # explicit Euler: poles 1 + s/fs outside the unit circle, the output grows without bound
    assert np.max(np.abs(model.euler_poles_z(RATE))) > 1.0
    with np.errstate(all="ignore"):
        naive = euler_accelerations(model, drive, sample_rate_hz=RATE)
        tail = naive[-RATE // 10 :]
        growth = np.sqrt(np.mean(tail**2)) / np.sqrt(np.mean(naive[: RATE // 10] ** 2))
    assert not np.all(np.isfinite(tail)) or growth > 1e3


@pytest.mark.parametrize("rate_hz", RATES_HZ)
def test_euler_becomes_unstable_exactly_where_the_analysis_says(rate_hz: int) -> None:
    # |1 + T s|^2 = 1 - T w0 / Q + (T w0)^2 for complex poles: unstable iff T w0 Q > 1
    for f0 in (50.0, 170.0, 0.1 * rate_hz):
        for q in (0.6, 2.0, 5.0, 50.0, 1000.0):
            tw = 2 * math.pi * f0 / rate_hz
            radius = np.max(np.abs(ActuatorModel(f0_hz=f0, q=q).euler_poles_z(rate_hz)))
            assert radius == pytest.approx(math.sqrt(1 - tw / q + tw * tw), rel=1e-9)
            assert (radius > 1.0) == (tw * q > 1.0)
