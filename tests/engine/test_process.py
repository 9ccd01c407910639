"""The engine in a process of its own: same samples, same API, gone with its host."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import soundfile

from phantomtouch import (
    DeviceProfile,
    EngineBusyError,
    ParameterError,
    ProtocolError,
    TouchPattern,
    plan,
    render,
)
from phantomtouch.engine import plans as plan_cache
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.errors import DeviceError
from phantomtouch.output.soundcard import SinkSpec
from tests.support.jack import JackRecorder, JackServer
from tests.support.waiting import wait_until
from tests.support.yardstick import WakeUpLag

DEVICE = DeviceProfile.default()
STROKE = TouchPattern.model_validate(
    {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 40.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
    }
)


def wait_for_state(engine: ProcessEngine, job_id: str, state: str) -> None:
    wait_until(lambda: engine.job_state(job_id).state == state, 10.0)  # type: ignore[union-attr]


def test_a_pattern_played_by_the_engine_process_is_the_offline_render(tmp_path: Path) -> None:
    wav = tmp_path / "played.wav"
    with ProcessEngine(DEVICE, SinkSpec("capture", wav_path=str(wav))) as engine:
        job = engine.schedule(STROKE, start_frame=engine.now_frames + 4801)
        wait_for_state(engine, job.job_id, "finished")
        state = engine.job_state(job.job_id)
    recording, rate = soundfile.read(wav, dtype="float32")
    reference = render(STROKE, DEVICE)
    assert rate == 48000 and state is not None and state.start_frame == job.start_frame
    played = recording[job.start_frame : job.start_frame + len(reference)]
    np.testing.assert_array_equal(played, reference)
    assert not np.any(recording[: job.start_frame])


def test_the_engine_process_answers_like_the_engine() -> None:
    engine = ProcessEngine(DEVICE, SinkSpec("null"), queue_capacity=1)
    try:
        engine.start()
        assert engine.pid is not None and engine.pid != os.getpid()
        now_s = engine.server_time_s()
        assert engine.time_at(engine.frames_at(now_s + 1.0)) == pytest.approx(now_s + 1.0, abs=1e-4)
        waiting = engine.schedule(STROKE, start_frame=engine.now_frames + 48000 * 60)
        with pytest.raises(EngineBusyError, match="full"):
            engine.schedule(STROKE)
        with pytest.raises(ParameterError, match="start_frame=-3"):
            engine.schedule(STROKE, start_frame=-3)
        assert engine.stop(waiting.job_id) is True
        assert engine.stop("no-such-job") is False
        wait_until(lambda: engine.status().queue_depth == 0, 10.0)  # freed at the next block
        engine.contact_down("client", "finger", 1.0, 2.0, intensity=0.4)
        with pytest.raises(ProtocolError, match="expected down, got move"):
            engine.contact_move("client", "thumb", 1.0, 2.0)
        with pytest.raises(ParameterError, match="x_cm=nan"):
            engine.contact_move("client", "finger", float("nan"), 2.0)
        engine.contact_move("client", "finger", 1.5, 3.0)
        time.sleep(0.05)
        status = engine.status()
        assert (status.backend, status.running, status.active_voices) == ("null", True, 1)
        assert status.active_contacts == [
            {"owner": "client", "contact": "finger", "x_cm": 1.5, "y_cm": 3.0}
        ]
        engine.release_owner("client")
        wait_until(lambda: engine.status().active_voices == 0, 10.0)
    finally:
        engine.close()
        engine.close()
    assert engine.status().state == "closed"
    with pytest.raises(DeviceError, match="closed"):
        engine.schedule(STROKE)


def test_stop_all_gets_through_before_anything_sent_after_it() -> None:
    with ProcessEngine(DEVICE, SinkSpec("null")) as engine:
        engine.contact_down("a", "1", 1.0, 2.0)
        job = engine.schedule(STROKE, start_frame=engine.now_frames + 48000)
        for k in range(200):  # a backlog of moves the child has yet to apply
            engine.contact_move("a", "1", 1.0, 2.0 + 0.01 * k)
        engine.stop_all()
        engine.contact_down("b", "1", 3.0, 9.0)
        status = engine.status()
        assert [c["owner"] for c in status.active_contacts] == ["b"]
        assert engine.job_state(job.job_id).state == "stopped"  # type: ignore[union-attr]


def test_the_engine_process_ends_when_its_host_dies(tmp_path: Path) -> None:
    script = tmp_path / "host.py"
    script.write_text(
        "import os, sys\n"
        "from phantomtouch import DeviceProfile\n"
        "from phantomtouch.engine.process import ProcessEngine\n"
        "from phantomtouch.output.soundcard import SinkSpec\n"
        "if __name__ == '__main__':\n"
        "    engine = ProcessEngine(DeviceProfile.default(), SinkSpec('null'))\n"
        "    engine.start()\n"
        "    engine.contact_down('host', 'finger', 1.0, 1.0)\n"
        "    print(engine.pid, flush=True)\n"
        "    os._exit(0)  # no close(): the host just vanishes\n",
        encoding="utf-8",
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    child = int(done.stdout.strip())
    deadline = time.monotonic() + 10.0
    while Path(f"/proc/{child}").exists() and "zombie" not in _state(child):
        assert time.monotonic() < deadline, "the engine process outlived its host"
        time.sleep(0.05)


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split("\n")[0].lower()
    except (OSError, IndexError):
        return "zombie"


def test_a_sink_the_child_cannot_open_is_a_device_error() -> None:
    with pytest.raises(DeviceError):
        ProcessEngine(DEVICE, SinkSpec("sounddevice", output="no such output device"))
    with pytest.raises(ParameterError, match="backend='alsa'"):
        SinkSpec("alsa")


def test_the_engine_process_plays_bit_exact_over_jack(jack_server: JackServer) -> None:
    engine = ProcessEngine(DEVICE, SinkSpec("sounddevice", "system"))
    recorder = JackRecorder(jack_server, max_frames=10 * 48000)
    try:
        # the child's PortAudio client ("PortAudio-01" or so when this process has one too)
        assert len(recorder.connect_from("PortAudio[^:]*")) == 8
        engine.start()
        job = engine.schedule(STROKE, start_frame=engine.now_frames + 9600)
        wait_for_state(engine, job.job_id, "finished")
    finally:
        engine.close()
        recording = recorder.close()
    reference = render(STROKE, DEVICE)
    at = int(np.flatnonzero(recording.any(axis=1))[0]) - int(
        np.flatnonzero(reference.any(axis=1))[0]
    )
    np.testing.assert_array_equal(recording[at : at + len(reference)], reference)
    assert not np.any(recording[at + len(reference) :])


def test_moves_through_shared_memory_reach_the_output(tmp_path: Path) -> None:
    wav = tmp_path / "moved.wav"
    with ProcessEngine(DEVICE, SinkSpec("capture", wav_path=str(wav))) as engine:
        engine.contact_down("hand", "1", 0.0, 0.0, intensity=0.5)  # on actuator 1
        time.sleep(0.1)
        for k in range(1, 101):  # a stroke to actuator 8, the last position wins
            engine.contact_move("hand", "1", 3.8 * k / 100, 14.4 * k / 100)
        time.sleep(0.2)
        moved_at = engine.now_frames
        time.sleep(0.1)
        engine.contact_up("hand", "1")
        with pytest.raises(ProtocolError, match="expected down, got move"):
            engine.contact_move("hand", "1", 1.0, 1.0)
        time.sleep(0.2)
    recording, _ = soundfile.read(wav, dtype="float32")
    first = int(np.flatnonzero(recording.any(axis=1))[0])
    before = np.abs(recording[first : first + 2400]).max(axis=0)
    after = np.abs(recording[moved_at : moved_at + 4800]).max(axis=0)
    assert before[0] > 0.1 and not np.any(before[1:])
    assert after[7] == pytest.approx(before[0], rel=1e-3) and not np.any(after[:7])
    assert not np.any(recording[-4800:])


def test_contacts_get_slots_up_to_max_contacts() -> None:
    settings = ContactSettings(max_contacts=2)
    with ProcessEngine(DEVICE, SinkSpec("null"), contact=settings) as engine:
        engine.contact_down("a", "1", 1.0, 2.0)
        engine.contact_down("a", "1", 1.5, 2.0)  # down again: the same contact, one slot
        engine.contact_down("b", "1", 1.0, 3.0)
        with pytest.raises(EngineBusyError, match="max_contacts=2"):
            engine.contact_down("b", "2", 1.0, 4.0)  # b holds one, and so does every other
        engine.contact_up("a", "1")
        engine.contact_down("c", "1", 1.0, 4.0)
        engine.contact_move("c", "1", 2.0, 5.0)
        engine.release_owner("b")
        engine.contact_down("d", "1", 1.0, 6.0)
        wait_until(
            lambda: (
                sorted((c["owner"], c["y_cm"]) for c in engine.status().active_contacts)
                == [("c", 5.0), ("d", 6.0)]
            ),
            10.0,
        )


def test_plans_sent_once_are_kept_and_forgotten_in_turn(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(plan_cache, "MAX_BYTES", 1)  # no plan kept: each handed, then dropped
    patterns = [STROKE.model_copy(update={"speed_cm_s": 10.0 + 5 * k}) for k in range(5)]
    plans = [plan(pattern, DEVICE) for pattern in patterns]
    with ProcessEngine(DEVICE, SinkSpec("null"), max_voices=100, voice_cost=1e-4) as engine:
        for round_ in range(3):
            for k, planned in enumerate(plans[: 2 + round_]):
                job = engine.schedule(planned, start_frame=engine.now_frames + 48000 * 30)
                assert job.frames == planned.frames, (round_, k)
                engine.stop(job.job_id)


def test_answers_reach_coroutines_and_threads_that_wait_at_once() -> None:
    plans = [plan(STROKE.model_copy(update={"speed_cm_s": 10.0 + k}), DEVICE) for k in range(6)]
    with ProcessEngine(
        DEVICE, SinkSpec("null"), queue_capacity=40, max_voices=100, voice_cost=1e-4
    ) as engine:  # no start budget: 60 jobs begin in one block
        later = engine.now_frames + 48000 * 60

        async def schedule_all() -> list[object]:
            calls = [
                engine.schedule_async(plans[k % 6], start_frame=later, owner=f"o{k}")
                for k in range(60)
            ]
            return await asyncio.gather(*calls, return_exceptions=True)

        seen: list[int] = []
        stop = threading.Event()

        def ask() -> None:  # a thread with calls that wait, between the coroutines' answers
            while not stop.is_set():
                seen.append(engine.status().queue_capacity)

        thread = threading.Thread(target=ask)
        thread.start()
        try:
            answers = asyncio.run(schedule_all())
        finally:
            stop.set()
            thread.join()
        jobs = [answer for answer in answers if not isinstance(answer, BaseException)]
        refused = [answer for answer in answers if isinstance(answer, BaseException)]
        assert len(jobs) == 40 and all(isinstance(e, EngineBusyError) for e in refused)
        for k, job in enumerate(answers):
            if not isinstance(job, BaseException):
                assert job.frames == plans[k % 6].frames  # type: ignore[attr-defined]
                assert engine.job_state(job.job_id).owner == f"o{k}"  # type: ignore[attr-defined,union-attr]
        assert seen and set(seen) == {40}


def test_closing_answers_what_waits_and_refuses_what_comes_after() -> None:
    engine = ProcessEngine(DEVICE, SinkSpec("null"))
    engine.start()

    async def schedule_then_close() -> None:
        pending = asyncio.ensure_future(engine.schedule_async(STROKE))
        await asyncio.sleep(0)  # sent
        engine.close()
        assert (await pending).frames == plan(STROKE, DEVICE).frames
        with pytest.raises(DeviceError, match="closed"):
            await engine.schedule_async(STROKE)

    asyncio.run(schedule_then_close())


def test_an_engine_process_killed_is_noticed_refused_and_restarted() -> None:
    faults: list[str] = []
    engine = ProcessEngine(DEVICE, SinkSpec("null"), on_fault=faults.append)
    try:
        engine.start()
        job = engine.schedule(STROKE)
        engine.contact_down("a", "1", 1.0, 2.0)
        old_pid = engine.pid
        assert old_pid is not None
        with WakeUpLag() as lag:  # 1 s and 0.1 s on a quiet machine, more on a busy one
            os.kill(old_pid, signal.SIGKILL)
            began = time.monotonic()
            wait_until(lambda: engine.state != "running", 10.0)
            noticed_s = time.monotonic() - began
            assert faults == ["gone"]
            assert engine.job_state(job.job_id).state == "stopped"  # type: ignore[union-attr]
            assert engine.status().active_contacts == []
            if engine.state != "running":  # refused with a clear error while it restarts
                with pytest.raises(DeviceError, match="restart"):
                    engine.schedule(STROKE)
            began = time.monotonic()
            engine.stop_all()  # never waits, whatever the engine's state
            stop_s = time.monotonic() - began
        assert noticed_s < 1.0 + 10 * lag.worst_s, (noticed_s, lag.worst_s)
        assert stop_s < 0.1 + 10 * lag.worst_s, (stop_s, lag.worst_s)
        wait_until(lambda: engine.state == "running", timeout_s=30.0)
        assert engine.pid != old_pid and engine.status().restarts == 1
        again = engine.schedule(STROKE)
        wait_until(lambda: engine.job_state(again.job_id).state == "playing", 10.0)  # type: ignore[union-attr]
    finally:
        engine.close()


def test_an_engine_process_stopped_is_noticed_and_replaced() -> None:
    faults: list[str] = []
    engine = ProcessEngine(DEVICE, SinkSpec("null"), on_fault=faults.append)
    try:
        engine.start()
        engine.schedule(STROKE)
        old_pid = engine.pid
        assert old_pid is not None
        os.kill(old_pid, signal.SIGSTOP)
        try:
            with WakeUpLag() as lag:  # 0.1 s and 1.5 s on a quiet machine
                began = time.monotonic()
                engine.stop_all()
                status = engine.status()  # answered at once from shared memory
                answered_s = time.monotonic() - began
                wait_until(lambda: engine.state != "running", 10.0)
                noticed_s = time.monotonic() - began
            assert answered_s < 0.1 + 10 * lag.worst_s and status.state == "running"
            assert noticed_s < 1.5 + 10 * lag.worst_s, (noticed_s, lag.worst_s)
            assert faults == ["stalled"]
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.kill(old_pid, signal.SIGCONT)
        wait_until(lambda: engine.state == "running", timeout_s=30.0)
        assert engine.pid != old_pid
    finally:
        engine.close()


def test_a_plan_sent_with_a_start_that_a_stop_voids_is_kept_for_the_next_start() -> None:
    planned = plan(STROKE, DEVICE)
    with ProcessEngine(DEVICE, SinkSpec("null")) as engine:
        for _ in range(3):
            voided = engine.schedule(planned)  # the plan crosses with this start ...
            engine.stop_all()  # ... which the stop voids before the engine reads it
            assert engine.job_state(voided.job_id).state == "stopped"  # type: ignore[union-attr]
            again = engine.schedule(planned)  # sent by its key alone
            wait_for_state(engine, again.job_id, "playing")
            engine.stop_all()
        assert engine.status().callback_errors == 0


def test_the_host_reads_the_callback_s_render_loads_from_shared_memory() -> None:
    with ProcessEngine(DEVICE, SinkSpec("null")) as engine:
        deadline = time.monotonic() + 5.0
        while engine.status().render_load_max == 0.0 and time.monotonic() < deadline:
            time.sleep(0.05)
        status = engine.status()
        assert 0.0 < status.render_load_p99 <= status.render_load_max


def test_a_release_gets_through_a_full_outbox() -> None:
    """An outbox at its limit refuses a new touch but never a release: the contact's voice
    ends (before, the release was dropped and the contact kept sounding)."""
    with ProcessEngine(DEVICE, SinkSpec("null")) as engine:
        engine.contact_down("a", "1", 1.0, 2.0)
        wait_until(lambda: engine.status().active_voices == 1, 10.0)
        engine._audio._child.outbox._max = 0  # as if the engine process fell that far behind
        with pytest.raises(EngineBusyError, match="pipe is full"):
            engine.contact_down("b", "1", 3.0, 9.0)
        engine.contact_up("a", "1")
        wait_until(lambda: engine.status().active_voices == 0, 10.0)


def test_engine_processes_starting_together_do_not_stall_one_that_plays() -> None:
    """An engine process starts up (its compiled loops loaded, its voices' costs measured:
    about a second of CPU) at normal priority and only then takes real-time priority. At
    real-time priority from the first, as many starting at once as the machine has cores
    (at most 4) held off an engine process already playing past its stall limit, which
    was then restarted (on a 2-core machine, in 5 of 9 rounds of two starting at once)."""
    faults: list[str] = []
    playing = ProcessEngine(DEVICE, SinkSpec("null"), on_fault=faults.append)
    starters = min(os.cpu_count() or 2, 4)

    def start_one(_: int) -> ProcessEngine:
        engine = ProcessEngine(DEVICE, SinkSpec("null"))
        engine.start()
        return engine

    try:
        playing.start()
        for _ in range(5):
            with ThreadPoolExecutor(starters) as pool:
                started = list(pool.map(start_one, range(starters)))
            for engine in started:
                engine.close()
        assert faults == [] and playing.status().restarts == 0
        assert playing.state == "running"
    finally:
        playing.close()
