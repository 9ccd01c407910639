"""The audio side knows jobs and contacts by the integers the front minted, never by names."""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest

from phantomtouch import DeviceProfile, TouchPattern
from phantomtouch.engine import Engine
from phantomtouch.engine.messages import Command, Ended, Event, Released, Started, VoiceEvent
from phantomtouch.output.sinks import CaptureSink

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
STROKE = TouchPattern.model_validate(
    {"path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]}, "speed_cm_s": 40.0}
)


def strings(value: object) -> Iterator[str]:
    """Every string in ``value``, through dataclasses, tuples, lists and dicts."""
    if isinstance(value, str):
        yield value
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            yield from strings(getattr(value, field.name))
    elif isinstance(value, tuple | list):
        for item in value:
            yield from strings(item)
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from strings(key)
            yield from strings(item)


class Crossing:
    """What crosses between the front and the audio side of an in-process engine: every
    message the front posts (through the audio side's one ``post``) and every event the
    audio side delivers."""

    def __init__(self, engine: Engine, monkeypatch: pytest.MonkeyPatch) -> None:
        self.messages: list[Command] = []
        self.events: list[Event] = []
        audio = engine._audio
        post, deliver = audio.post, audio._links.deliver

        def posting(message: Command) -> None:
            self.messages.append(message)
            post(message)

        def delivering(events: list[Event]) -> None:
            self.events.extend(events)
            deliver(events)

        monkeypatch.setattr(audio, "post", posting)
        monkeypatch.setattr(audio, "_links", dataclasses.replace(audio._links, deliver=delivering))

    def keys(self, kind: str) -> list[int]:
        """The keys of the voice events of ``kind``, in the order they came."""
        return [e.key for e in self.events if isinstance(e, VoiceEvent) and e.kind == kind]


def test_no_message_or_event_and_no_table_of_the_audio_side_holds_a_name(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, prerender_max_s=0.0) as engine:
        crossing = Crossing(engine, monkeypatch)
        job = engine.schedule(STROKE, owner="owner-of-job")
        engine.contact_down("owner-of-hand", "hand-1", 1.0, 2.0)
        engine.contact_down("owner-of-hand", "hand-2", 1.5, 6.0)
        engine.contact_down("owner-of-foot", "foot-1", 1.0, 9.0)
        engine.contact_move("owner-of-hand", "hand-1", 1.2, 3.0, intensity=0.4)
        sink.pull(4)
        core = engine.core
        tables = [*core._jobs, *core.board._contacts]
        voices = [voice.key for voice in core.scheduler._voices]
        engine.stop(job.job_id)
        engine.contact_up("owner-of-foot", "foot-1")
        engine.release_owner("owner-of-hand")
        sink.pull(20)
        engine.job_state(job.job_id)  # hands the events over
    names = {job.job_id, "owner-of-job", "owner-of-hand", "hand-1", "hand-2"}
    names |= {"owner-of-foot", "foot-1"}
    assert len(tables) == 4 and len(voices) == 4
    assert all(type(key) is int for key in tables + voices)
    assert all(type(key) is int for key in crossing.keys("job") + crossing.keys("contact"))
    assert len(set(crossing.keys("contact"))) == 3
    posted = {type(message).__name__ for message in crossing.messages}
    assert posted >= {"StartJob", "ReleaseJob", "ContactDown", "ContactMove", "ContactUp"}
    assert len(crossing.events) == 3 * 4  # each voice started, released, ended
    for crossed in crossing.messages + crossing.events:
        assert not names & set(strings(crossed)), crossed


def test_a_contact_down_again_is_a_new_integer_and_the_old_voices_events_keep_to_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    path = tmp_path / "stimuli.jsonl"
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, log_path=path) as engine:
        crossing = Crossing(engine, monkeypatch)
        engine.contact_down("vr", "hand", 1.0, 2.0)
        sink.pull(2)
        engine.contact_up("vr", "hand")
        engine.contact_down("vr", "hand", 1.5, 9.0)  # while the first still fades out
        sink.pull(20)  # the first ends, the second sounds on
        engine._audio.sync()
        events = [e for e in crossing.events if isinstance(e, VoiceEvent)]
        old, new = dict.fromkeys(e.key for e in events)  # two integers, in order
        assert list(engine.core.board._contacts) == [new]  # the stale end left it sounding
        assert engine.core.scheduler.active_voices == 1 and engine.holds("vr", "hand")
    assert [(type(e), e.key) for e in events if e.key == new] == [(Started, new)]
    assert [type(e) for e in events if e.key == old] == [Started, Released, Ended]
    starts = [e for e in events if isinstance(e, Started)]
    assert [(e.key, e.y_cm) for e in starts] == [(old, 2.0), (new, 9.0)]
    records = [json.loads(line) for line in path.read_text().splitlines()]
    assert {(r["kind"], r["owner"], r["contact"]) for r in records} == {("contact", "vr", "hand")}
    assert Counter(r["event"] for r in records) == {"start": 2, "release": 1, "end": 1}
