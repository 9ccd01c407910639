import json

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, plan, render
from phantomtouch.analysis.accuracy import (
    CRITERIA,
    Row,
    Setting,
    effective_gains,
    gain_centroid,
    intended_path,
    measure,
    meets_criteria,
    recommend,
    reference_strokes,
    run_accuracy,
)
from phantomtouch.analysis.accuracy_report import format_table, save_plot
from phantomtouch.renderer.carriers import SineSource

BASE = DeviceProfile.default()


def straight(speed_cm_s: float, mode: str = "2d") -> TouchPattern:
    # inside one triangle of the default layout (lower-right of the lowest cell)
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[3.0, 0.5], [3.4, 4.0]]},
            "speed_cm_s": speed_cm_s,
            "fade_in_s": 0.05,
            "fade_out_s": 0.05,
            "carrier": {"kind": "sine", "freq_hz": 100.0},
            "intensity": "low",
            "mode": mode,
        }
    )


@pytest.mark.parametrize(
    "setting", [Setting(1, True), Setting(32, True), Setting(32, False), Setting(100, True)]
)
@pytest.mark.parametrize("stroke", ["exp1-v18", "zigzag-v100"])
def test_effective_gains_are_what_the_renderer_multiplies_the_carrier_with(
    setting: Setting, stroke: str
) -> None:
    pattern = reference_strokes()[stroke]
    device = setting.device(BASE)
    resolved = plan(pattern, device)
    carrier = SineSource(100.0, resolved.sample_rate_hz).block(0, resolved.frames)
    expected = carrier[:, None] * effective_gains(resolved)
    # float32 products in another order: a few ulps of the amplitude
    np.testing.assert_allclose(render(pattern, device), expected, rtol=0, atol=1e-6 * 0.05)


@pytest.mark.parametrize("stroke", list(reference_strokes()))
def test_per_frame_power_law_gains_put_the_centroid_on_the_path(stroke: str) -> None:
    resolved = plan(reference_strokes()[stroke], BASE.model_copy(update={"gain_update_frames": 1}))
    times = np.arange(resolved.frames) / resolved.sample_rate_hz
    intended, envelope = intended_path(resolved, times)
    centroid = gain_centroid(effective_gains(resolved), resolved.geometry)
    sounding = envelope > 0
    # float32 gains: centroid exact to ~1e-6 of the band's size
    np.testing.assert_allclose(centroid[sounding], intended[sounding], atol=1e-4)


@pytest.mark.parametrize("frames", [8, 64, 512])
def test_held_gains_lag_by_at_most_the_distance_of_one_update(frames: int) -> None:
    speed, rate = 50.0, BASE.sample_rate_hz
    pattern = straight(speed)
    reference = effective_gains(plan(pattern, Setting(1, True).device(BASE)))
    held = measure(
        "straight", pattern, Setting(frames, False), base=BASE, reference_gains=reference
    )
    # a held gain is the point's position at the last update: the error is the distance
    # travelled since, (frames - 1) / rate s at most; inside one triangle exactly that
    bound = speed * (frames - 1) / rate
    assert held.position_error_gains_max_cm == pytest.approx(bound, rel=1e-3)
    ramped = measure(
        "straight", pattern, Setting(frames, True), base=BASE, reference_gains=reference
    )
    assert ramped.position_error_gains_max_cm < held.position_error_gains_max_cm


def test_errors_grow_with_the_update_interval() -> None:
    report = run_accuracy(
        {"exp2-curved": reference_strokes()["exp2-curved"]},
        [Setting(1, True), Setting(8, True), Setting(128, True), Setting(128, False)],
        repeats=1,
    )
    rows = {r.setting: r for r in report.rows}
    per_frame, r8, r128 = rows["1 (per frame)"], rows["8 ramp"], rows["128 ramp"]
    assert per_frame.gain_error_max == 0.0 and per_frame.position_error_gains_max_cm < 1e-4
    assert r8.position_error_gains_max_cm < r128.position_error_gains_max_cm
    assert r8.gain_error_rms < r128.gain_error_rms < rows["128 hold"].gain_error_rms
    # the study's CPU yardstick is the per-frame render of the same run
    assert per_frame.cpu_relative == 1.0
    assert report.recommended in rows
    table = format_table(report)
    assert all(label in table for label in rows)
    json.dumps(report.to_dict())


def test_plot_is_written(tmp_path) -> None:
    pytest.importorskip("matplotlib")
    report = run_accuracy(
        {"exp2-curved": reference_strokes()["exp2-curved"]}, [Setting(32, True)], repeats=1
    )
    save_plot(report, tmp_path / "accuracy.png")
    assert (tmp_path / "accuracy.png").read_bytes()[:4] == b"\x89PNG"


def row(setting: str, frames: int, ramp: bool, cpu: float, **errors: float) -> Row:
    values = {
        "gain_error_max": 0.0,
        "gain_error_rms": 0.0,
        "position_error_gains_max_cm": 0.0,
        "position_error_gains_rms_cm": 0.0,
        "level_error_gains_max_db": 0.0,
        "position_error_twin_max_cm": 0.1,
        "position_error_twin_rms_cm": 0.0,
        "level_variation_twin_db": 0.5,
        "silent_windows_twin": 0,
        **errors,
    }
    return Row(setting, frames, ramp, cpu_ms_per_s=cpu, cpu_blocks_ms_per_s=cpu, **values)


def test_recommend_takes_the_cheapest_accurate_ramped_setting() -> None:
    limit = CRITERIA["position_error_max_cm"]
    rows = [
        row("1", 1, True, 10.0),
        row("32 ramp", 32, True, 1.0),
        row("128 ramp", 128, True, 0.7, position_error_gains_max_cm=limit / 2),
        row("128 hold", 128, False, 0.5),  # cheapest, but held gains step
        row("512 ramp", 512, True, 0.6, position_error_gains_max_cm=2 * limit),
    ]
    assert recommend(rows) == "128 ramp"
    assert [r.meets_criteria for r in rows] == [True, True, True, False, False]


def test_recommend_prefers_fewer_frames_when_the_cost_ties() -> None:
    rows = [row("1", 1, True, 10.0), row("32 ramp", 32, True, 1.05), row("128 ramp", 128, True, 1)]
    assert recommend(rows) == "32 ramp"


def test_recommend_judges_the_twin_beyond_the_per_frame_floor() -> None:
    level = CRITERIA["level_error_max_db"]
    rows = [
        row("1", 1, True, 10.0, level_variation_twin_db=0.6),
        row("8 ramp", 8, True, 2.0, level_variation_twin_db=0.6 + level / 2),
        row("32 ramp", 32, True, 1.0, level_variation_twin_db=0.6 + 2 * level),
    ]
    assert recommend(rows) == "8 ramp"
    assert recommend(rows[1:]) is None  # no per-frame floor to judge against
    rows[1].silent_windows_twin = 1  # a setting that leaves a felt window silent fails
    assert recommend(rows) == "1"


@pytest.mark.parametrize("sample_rate_hz", [8000, 48000, 192000])
def test_the_default_control_interval_meets_the_criteria_at_every_rate(
    sample_rate_hz: int,
) -> None:
    # The interval is a time: at 8 kHz 21 frames, at 192 kHz 512, always about 2.67 ms,
    # so the phantom moves as far between two updates whatever the rate.
    device = BASE.model_copy(update={"sample_rate_hz": sample_rate_hz})
    step = device.gain_step_frames
    assert step == round(device.gain_update_s * sample_rate_hz)
    strokes = {name: reference_strokes()[name] for name in ("zigzag-v100", "stop-and-go")}
    report = run_accuracy(
        strokes, [Setting(1, True), Setting(step, True)], device=device, repeats=1
    )
    floor, default = report.rows
    assert meets_criteria(default, floor), (
        default.position_error_gains_max_cm,
        default.level_error_gains_max_db,
        default.position_error_twin_max_cm - floor.position_error_twin_max_cm,
        default.level_variation_twin_db - floor.level_variation_twin_db,
    )


def test_a_count_of_frames_would_miss_the_criteria_at_8_khz() -> None:
    # What the time-based interval avoids: 128 frames at 8 kHz are 16 ms.
    device = BASE.model_copy(update={"sample_rate_hz": 8000})
    strokes = {"zigzag-v100": reference_strokes()["zigzag-v100"]}
    report = run_accuracy(strokes, [Setting(1, True), Setting(128, True)], device=device, repeats=1)
    floor, frames_128 = report.rows
    assert not meets_criteria(frames_128, floor)
