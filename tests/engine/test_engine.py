"""The engine's API, driven block by block through a CaptureSink (deterministic)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest

from phantomtouch import DeviceProfile, EngineBusyError, ParameterError, TouchPattern, render
from phantomtouch.engine import Engine, Job
from phantomtouch.errors import DeviceError
from phantomtouch.output.sinks import CaptureSink, NullSink
from phantomtouch.renderer import plan
from phantomtouch.schema import Calibration

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
RELEASE = round(0.08 * DEVICE.sample_rate_hz)


def stroke(**changes: object) -> TouchPattern:
    fields: dict[str, object] = {
        "path": {"kind": "polyline", "points_cm": [[0.4, 13.0], [3.4, 1.0]]},
        "speed_cm_s": 60.0,
        "fade_in_s": 0.02,
        "fade_out_s": 0.02,
    }
    fields.update(changes)
    return TouchPattern.model_validate(fields)


@pytest.fixture
def captured() -> Iterator[tuple[Engine, CaptureSink]]:
    sink = CaptureSink(DEVICE)
    engine = Engine(DEVICE, sink)
    engine.start()
    yield engine, sink
    engine.close()


def pull_until(sink: CaptureSink, frame: int) -> np.ndarray:
    """Pull whole blocks until the recording covers ``frame``; the whole recording."""
    missing = frame - sink.frames
    if missing > 0:
        sink.pull(-(-missing // BLOCK))
    return sink.recording()


@pytest.mark.parametrize("start_frame", [0, 1000, 3 * BLOCK, 5 * BLOCK - 1])
def test_a_pattern_starts_at_its_sample_inside_a_block(
    captured: tuple[Engine, CaptureSink], start_frame: int
) -> None:
    engine, sink = captured
    pattern = stroke(carrier={"kind": "combined", "seed": 3})
    job = engine.schedule(pattern, start_frame=start_frame)
    reference = render(pattern, DEVICE)
    recording = pull_until(sink, start_frame + len(reference) + BLOCK)
    expected = np.zeros_like(recording)
    expected[start_frame : start_frame + len(reference)] = reference
    np.testing.assert_array_equal(recording, expected)
    state = engine.job_state(job.job_id)
    assert state is not None
    assert (state.state, state.start_frame, state.end_frame, state.late) == (
        "finished",
        start_frame,
        start_frame + job.frames,
        False,
    )


def test_overlapping_patterns_sum_and_calibration_applies_once_after_the_sum() -> None:
    device = DeviceProfile(
        calibration=Calibration(channel_level_db=(155, 152, 158, 155, 149, 155, 156, 150))
    )
    first, second = (
        stroke(),
        stroke(
            path={
                "kind": "arc",
                "start_cm": [3.8, 12],
                "through_cm": [0, 7.2],
                "end_cm": [3.8, 2.4],
            }
        ),
    )
    sink = CaptureSink(device)
    with Engine(device, sink) as engine:
        engine.schedule(first, start_frame=100)
        engine.schedule(second, start_frame=2000)
        alone_a, alone_b = render(first, device), render(second, device)
        recording = pull_until(sink, 2000 + max(len(alone_a), len(alone_b)) + BLOCK)
    expected = np.zeros_like(recording, dtype=np.float64)
    expected[100 : 100 + len(alone_a)] += alone_a
    expected[2000 : 2000 + len(alone_b)] += alone_b
    # calibration is linear: sum then calibrate == calibrate then sum, to float32 rounding
    np.testing.assert_allclose(recording, expected, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(recording[100:2000], alone_a[:1900])  # one voice: exact


def test_a_plan_can_be_scheduled_and_a_foreign_plan_is_refused(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, _ = captured
    planned = plan(stroke(), DEVICE)
    job = engine.schedule(planned, start_frame=10)
    assert (job.frames, job.summary) == (planned.frames, planned.summary())
    other = DeviceProfile(sample_rate_hz=44100)
    with pytest.raises(ParameterError, match="Plan for device"):
        engine.schedule(plan(stroke(), other))
    with pytest.raises(ParameterError, match="TouchPattern or a Plan"):
        engine.schedule("exp2/curved")  # type: ignore[arg-type]


def test_as_soon_as_possible_starts_with_the_next_block(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    sink.pull(3)
    job = engine.schedule(stroke())
    assert job.start_frame == 3 * BLOCK
    reference = render(stroke(), DEVICE)
    recording = pull_until(sink, 3 * BLOCK + len(reference))
    np.testing.assert_array_equal(recording[3 * BLOCK : 3 * BLOCK + len(reference)], reference)
    assert engine.status().late_commands == 0


def test_a_late_command_starts_at_once_and_is_counted(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    sink.pull(4)
    job = engine.schedule(stroke(), start_frame=BLOCK + 10)  # already played
    sink.pull(1)
    state = engine.job_state(job.job_id)
    assert state is not None and state.late and state.state == "playing"
    assert state.start_frame == 4 * BLOCK and state.requested_start_frame == BLOCK + 10
    assert engine.status().late_commands == 1
    reference = render(stroke(), DEVICE)
    np.testing.assert_array_equal(sink.recording()[4 * BLOCK :], reference[:BLOCK])


def test_job_states_go_scheduled_playing_finished(captured: tuple[Engine, CaptureSink]) -> None:
    engine, sink = captured
    job = engine.schedule(stroke(), start_frame=2 * BLOCK + 5, owner="client-7")
    assert isinstance(job, Job) and job.duration_s == pytest.approx(
        job.frames / 48000, abs=1 / 48000
    )
    states = []
    for _ in range(2 + job.frames // BLOCK + 2):
        state = engine.job_state(job.job_id)
        assert state is not None
        states.append(state.state)
        sink.pull(1)
    assert states[0] == "scheduled" and states[-1] == "finished"
    assert sorted(set(states), key=states.index) == ["scheduled", "playing", "finished"]
    final = engine.job_state(job.job_id)
    assert final is not None and final.owner == "client-7"
    assert final.to_dict()["end_frame"] == 2 * BLOCK + 5 + job.frames
    assert engine.job_state("no-such-job") is None
    assert engine.stop(job.job_id) is False  # already over
    assert engine.stop("no-such-job") is False


def test_a_stopped_job_fades_out_over_the_release_without_a_click(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    pattern = stroke(speed_cm_s=5.0)  # long enough to be stopped in its middle
    job = engine.schedule(pattern, start_frame=0)
    sink.pull(40)
    assert engine.stop(job.job_id) is True
    assert engine.stop(job.job_id) is False  # already stopping
    recording = pull_until(sink, 40 * BLOCK + RELEASE + 2 * BLOCK)
    reference = render(pattern, DEVICE)[: len(recording)]
    stop = 40 * BLOCK
    fade = np.clip((stop + RELEASE - 1 - np.arange(len(recording))) / RELEASE, 0.0, 1.0)
    np.testing.assert_array_equal(recording[:stop], reference[:stop])
    # float32 gains and product: within a few ulps of the analytic fade
    np.testing.assert_allclose(recording, reference * fade[:, None], rtol=1e-6, atol=1e-9)
    assert not np.any(recording[stop + RELEASE - 1 :])
    state = engine.job_state(job.job_id)
    assert state is not None
    assert (state.state, state.end_frame) == ("stopped", stop + RELEASE - 1)


def test_a_job_stopped_before_it_starts_never_sounds(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    job = engine.schedule(stroke(), start_frame=10 * BLOCK)
    sink.pull(2)
    assert engine.stop(job.job_id)
    recording = pull_until(sink, 10 * BLOCK + job.frames)
    assert not np.any(recording)
    state = engine.job_state(job.job_id)
    assert state is not None and (state.state, state.end_frame) == ("stopped", 10 * BLOCK)
    assert engine.status().queue_depth == 0


def test_max_voices_bounds_the_voices_that_sound_at_once_not_those_scheduled() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, max_voices=3, voice_policy="refuse") as engine:
        first = engine.schedule(stroke(), start_frame=100 * BLOCK)
        frames = first.frames
        # Two more overlap the first one (one starts in its middle): three sound at once.
        engine.schedule(stroke(), start_frame=100 * BLOCK)
        engine.schedule(stroke(), start_frame=100 * BLOCK + frames // 2)
        with pytest.raises(EngineBusyError, match="the voice budget allows 3"):
            engine.schedule(stroke(), start_frame=100 * BLOCK + frames // 2)
        # Jobs that start after the first two end overlap only the third: accepted.
        later = 100 * BLOCK + frames
        engine.schedule(stroke(), start_frame=later)
        engine.schedule(stroke(), start_frame=later)
        with pytest.raises(EngineBusyError, match="3 pattern voices would sound at once"):
            engine.schedule(stroke(), start_frame=later)
        # Far later, nothing overlaps: many jobs may wait in line as long as they do not.
        for k in range(10):
            engine.schedule(stroke(), start_frame=200 * BLOCK + 2 * k * frames)


def test_a_full_queue_refuses_new_work_but_stop_all_always_gets_through() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, queue_capacity=3) as engine:
        engine.contact_down("client", "finger", 1.0, 1.0, intensity=0.5)
        sink.pull(2)  # the contact plays: its slot in the queue is free again
        waiting = [engine.schedule(stroke(), start_frame=100 * BLOCK) for _ in range(3)]
        with pytest.raises(EngineBusyError, match="full"):
            engine.schedule(stroke(), start_frame=100 * BLOCK)
        with pytest.raises(EngineBusyError):
            engine.contact_down("client", "thumb", 1.0, 1.0)
        assert engine.status().queue_depth == 3
        engine.stop_all()
        after = engine.schedule(stroke(), start_frame=4 * BLOCK + RELEASE)  # accepted again
        recording = pull_until(sink, 100 * BLOCK + 2 * BLOCK)
        states = {job.job_id: engine.job_state(job.job_id) for job in [*waiting, after]}
        status = engine.status()
    assert status.queue_depth == 0
    assert all(states[job.job_id].state == "stopped" for job in waiting)  # type: ignore[union-attr]
    assert states[after.job_id].state == "finished"  # type: ignore[union-attr]
    silent_from = 2 * BLOCK + RELEASE - 1
    start = after.start_frame
    assert not np.any(recording[silent_from:start])
    np.testing.assert_array_equal(recording[start : start + after.frames], render(stroke(), DEVICE))
    assert not np.any(recording[start + after.frames :])


def test_stop_all_silences_contacts_too_and_forgets_them(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("a", "1", 1.0, 2.0, intensity=0.5)
    engine.contact_down("b", "1", 3.0, 9.0, intensity=0.5)
    sink.pull(4)
    engine.stop_all()
    assert engine.status().active_contacts == []
    recording = pull_until(sink, 4 * BLOCK + RELEASE + BLOCK)
    assert np.any(recording[4 * BLOCK])
    assert not np.any(recording[4 * BLOCK + RELEASE - 1 :])
    engine.contact_up("a", "1")  # no longer down: ignored


def test_release_owner_releases_only_that_clients_contacts(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("gone", "left", 0.0, 1.0, intensity=0.4)
    engine.contact_down("gone", "right", 0.0, 13.0, intensity=0.4)
    engine.contact_down("stays", "thumb", 3.8, 14.4, intensity=0.4)
    sink.pull(4)
    engine.release_owner("gone")
    engine.release_owner("nobody")
    assert engine.status().active_contacts == [
        {"owner": "stays", "contact": "thumb", "x_cm": 3.8, "y_cm": 14.4}
    ]
    recording = pull_until(sink, 4 * BLOCK + RELEASE + 2 * BLOCK)
    after = recording[4 * BLOCK + RELEASE - 1 :]
    channel_of_gone = [0, 3]  # actuators 1 (x=0, y=0) and 4 (x=0, y=14.4)
    assert not np.any(after[:, channel_of_gone])
    assert np.abs(after[:, 7]).max() > 0.01  # actuator 8 (x=3.8, y=14.4) still vibrates
    assert engine.status().active_voices == 1


def test_the_clock_maps_frames_and_server_time_both_ways(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, _ = captured
    now_s = engine.server_time_s()
    frame = engine.frames_at(now_s + 0.5)
    assert engine.time_at(frame) == pytest.approx(now_s + 0.5, abs=1 / 48000)
    assert engine.frames_at(engine.time_at(123456)) == 123456
    with pytest.raises(ParameterError, match="server_time_s"):
        engine.frames_at(float("nan"))


def test_arguments_out_of_range_are_refused_with_their_name(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, _ = captured
    with pytest.raises(ParameterError, match="start_frame=-1"):
        engine.schedule(stroke(), start_frame=-1)
    with pytest.raises(ParameterError, match=r"start_frame=\d+ is .* ahead"):
        engine.schedule(stroke(), start_frame=48000 * 7200)
    with pytest.raises(ParameterError, match="owner="):
        engine.schedule(stroke(), owner="")
    with pytest.raises(ParameterError, match="queue_capacity=0"):
        Engine(DEVICE, queue_capacity=0)


def test_a_sink_at_another_rate_is_refused_and_a_sinks_block_is_the_engines() -> None:
    with pytest.raises(DeviceError, match="sample_rate_hz=44100"):
        Engine(DEVICE, NullSink(DeviceProfile(sample_rate_hz=44100)))
    engine = Engine(DEVICE, NullSink(DeviceProfile(block_frames=128)))
    try:  # the sink's period is the engine's block, whatever the profile said
        assert DEVICE.block_frames != 128
        assert engine.block_frames == engine.device.block_frames == 128
        assert engine.device == DEVICE.at_block(128)
    finally:
        engine.close()


def test_close_is_idempotent_and_a_closed_engine_refuses_work() -> None:
    engine = Engine(DEVICE)
    engine.start()
    engine.close()
    engine.close()
    with pytest.raises(DeviceError, match="closed"):
        engine.schedule(stroke())
    with pytest.raises(DeviceError, match="closed"):
        engine.start()
    engine.stop_all()  # still never raises


def test_the_null_sink_plays_in_real_time() -> None:
    with Engine(DEVICE) as engine:
        began_s = engine.server_time_s()
        job = engine.schedule(stroke())
        status = engine.status()
        assert (status.backend, status.output_device, status.running) == ("null", None, True)
        while engine.job_state(job.job_id).state != "finished":  # type: ignore[union-attr]
            assert engine.server_time_s() < began_s + job.duration_s + 2.0
            time.sleep(0.002)
        took_s = engine.server_time_s() - began_s
    # blocks are pulled at the pace of the clock: the pattern takes its duration, not less
    assert took_s >= job.duration_s - 2 * BLOCK / 48000


def test_the_render_load_is_each_block_s_time_over_its_playing_time(
    captured: tuple[Engine, CaptureSink], monkeypatch: pytest.MonkeyPatch
) -> None:
    engine, sink = captured
    assert (engine.status().render_load_p99, engine.status().render_load_max) == (0.0, 0.0)
    block_s = BLOCK / DEVICE.sample_rate_hz
    ticks = iter(np.arange(0.0, 1000.0, 0.5 * block_s))  # each render: half a period
    monkeypatch.setattr(time, "monotonic", lambda: float(next(ticks)))
    sink.pull(10)
    monkeypatch.undo()
    status = engine.status()
    assert status.render_load_p99 == pytest.approx(0.5)
    assert status.render_load_max == pytest.approx(0.5)
