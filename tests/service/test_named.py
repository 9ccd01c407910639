"""A handle's named plays (phantomtouch/service/admission/named.py): what a source plays by
name, read from a real engine's tables (rendering into a capture sink at real-time pace):
a name stops playing when the engine stops its jobs or a stop comes, stays for its length
when its job played out, and a stop by name stops only that name's jobs and contacts."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from phantomtouch.clips.tact_score import Score, Voice
from phantomtouch.engine import Engine
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile, TouchPattern
from phantomtouch.service.admission import Admission, Handle, policy_table
from phantomtouch.service.scores import ScoreJobs
from tests.support.service import make_settings

DEVICE = DeviceProfile.default()


def still(duration_s: float) -> TouchPattern:
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 7.0]]},
            "duration_s": duration_s,
            "fade_in_s": 0.01,
            "fade_out_s": 0.01,
        }
    )


@pytest.fixture
def engine() -> Iterator[Engine]:
    with Engine(DEVICE, CaptureSink(DEVICE, realtime=True)) as engine:
        yield engine


@pytest.fixture
def admission(engine: Engine, tmp_path: Path) -> Admission:
    return Admission(engine, policy_table(make_settings(tmp_path)))


@pytest.fixture
def handle(admission: Admission) -> Handle:
    return admission.open("bhaptics", "1-game", principal="bhaptics:127.0.0.1")


def play(
    handle: Handle, name: str, duration_s: float, *, length_s: float | None = None
) -> ScoreJobs:
    """A one-voice score of ``duration_s`` s played and named ``name`` for ``length_s`` s
    (None: the score's length)."""
    score = Score((Voice(0.0, still(duration_s)),), length_s or duration_s)
    arrival = handle.arrival()
    scheduled = handle.play_score(score, arrival=arrival)
    assert handle.named.start(
        name, score, stop_count=arrival.stop_count, ends_s=scheduled.ends_s, jobs=scheduled.jobs
    )
    return scheduled


def names(handle: Handle) -> list[str | int]:
    return [named.name for named in handle.named.playing()]


def wait_for_state(engine: Engine, job_id: str, state: str, timeout_s: float = 5.0) -> None:
    deadline_s = time.monotonic() + timeout_s
    while (found := engine.job_state(job_id)) is None or found.state != state:
        assert time.monotonic() < deadline_s, f"job {job_id} still {found}"
        time.sleep(0.02)


def test_a_name_stops_playing_when_the_engine_stops_its_job(handle: Handle, engine: Engine) -> None:
    first = play(handle, "hit", 3.0)
    play(handle, "other", 3.0)
    assert names(handle) == ["hit", "other"]
    assert engine.stop(first.jobs[0])  # as DELETE /jobs/{id} does: nothing told the name
    assert names(handle) == ["other"]
    assert "hit" not in handle.named


def test_a_name_whose_job_played_out_stays_for_its_length(handle: Handle, engine: Engine) -> None:
    scheduled = play(handle, "tail", 0.1, length_s=1.0)
    wait_for_state(engine, scheduled.jobs[0], "finished")
    now_s = engine.server_time_s()
    assert now_s < scheduled.ends_s
    [named] = handle.named.playing(now_s)
    assert named.name == "tail" and named.jobs == []  # a job seen over is not asked again
    assert handle.named.playing(scheduled.ends_s) == []


def test_a_stop_ends_every_name_sent_before_it_and_voids_one_sent_before_it_after(
    admission: Admission, handle: Handle
) -> None:
    play(handle, "key", 3.0)
    handle.down("f1-0", 1.9, 7.0)
    arrival = handle.arrival()
    assert handle.named.start(
        "frame", "a frame", stop_count=arrival.stop_count, ends_s=math.inf, contacts="f1-"
    )
    admission.stop_all()  # POST /stop
    assert names(handle) == []
    assert len(handle.named) == 0
    assert not handle.named.start("late", "a frame", stop_count=arrival.stop_count)
    assert len(handle.named) == 0


def test_stopping_a_name_stops_only_its_jobs_and_contacts(handle: Handle, engine: Engine) -> None:
    one = play(handle, "one", 3.0)
    two = play(handle, "two", 3.0)
    for contact in ("fa-0", "fa-1", "fb-0"):
        handle.down(contact, 1.9, 7.0)
    stops = handle.stop_count
    handle.named.start("a", "frame a", stop_count=stops, ends_s=math.inf, contacts="fa-")
    handle.named.start("b", "frame b", stop_count=stops, ends_s=math.inf, contacts="fb-")
    assert handle.named.stop("one")  # turnOff "one"
    assert handle.named.stop("a")
    assert not handle.named.stop("a")
    assert engine.job_state(one.jobs[0]).state == "stopped"  # type: ignore[union-attr]
    assert engine.job_state(two.jobs[0]).state != "stopped"  # type: ignore[union-attr]
    assert handle.contacts() == ["fb-0"]
    assert names(handle) == ["two", "b"]
    assert handle.named.stop_all() == 2  # turnOffAll
    assert handle.contacts() == [] and names(handle) == []
    assert engine.job_state(two.jobs[0]).state == "stopped"  # type: ignore[union-attr]


def test_a_name_past_its_end_lifts_its_contacts(handle: Handle, engine: Engine) -> None:
    handle.down("fx-0", 1.9, 7.0)
    ends_s = engine.server_time_s() + 0.5
    handle.named.start("x", "frame", stop_count=handle.stop_count, ends_s=ends_s, contacts="fx-")
    assert names(handle) == ["x"] and handle.contacts() == ["fx-0"]
    assert handle.named.playing(ends_s) == []
    assert handle.contacts() == []


def test_a_new_play_of_a_name_takes_over_its_contacts_and_a_bound_ends_the_oldest(
    handle: Handle,
) -> None:
    stops = handle.stop_count
    for name in ("a", "b"):
        handle.down(f"f{name}-0", 1.9, 7.0)
        handle.named.start(name, 1, stop_count=stops, contacts=f"f{name}-", group="f", most=2)
    handle.named.start("a", 2, stop_count=stops, contacts="fa-", group="f", most=2)  # glides
    assert handle.contacts() == ["fa-0", "fb-0"]
    assert [(p.name, p.what) for p in handle.named.plays()] == [("b", 1), ("a", 2)]
    handle.named.start("c", 1, stop_count=stops, group="f", most=2)  # the oldest, b, ends
    assert [p.name for p in handle.named.plays()] == ["a", "c"]
    assert handle.contacts() == ["fa-0"]
    handle.named.start("k", "a key", stop_count=stops)  # no group: no bound
    assert len(handle.named) == 3


def test_until_ends_a_play_that_keeps_its_own_course_and_on_stop_is_called(
    handle: Handle,
) -> None:
    done = [False]
    stopped: list[int] = []
    handle.named.start(7, "loop", stop_count=None, until=lambda: done[0])
    handle.named.start(8, "loop", stop_count=None, on_stop=lambda: stopped.append(8))
    assert names(handle) == [7, 8]
    done[0] = True
    assert names(handle) == [8]
    handle.named.stop(8)
    assert stopped == [8]


def test_closing_the_handle_forgets_every_name_and_a_play_after_is_stopped(
    handle: Handle, engine: Engine
) -> None:
    play(handle, "key", 3.0)
    late = handle.play_score(Score((Voice(0.0, still(3.0)),), 3.0), arrival=handle.arrival())
    handle.close()
    assert len(handle.named) == 0
    assert not handle.named.start("late", "key", stop_count=handle.stop_count, jobs=late.jobs)
    assert engine.job_state(late.jobs[0]).state == "stopped"  # type: ignore[union-attr]
