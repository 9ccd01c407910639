"""Typed messages: one class and one applier per command, events typed alike."""

from __future__ import annotations

import dataclasses
import pickle
import pickletools

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, plan
from phantomtouch.engine import Engine, messages
from phantomtouch.engine.messages import (
    APPLIERS,
    AudioState,
    Cancelled,
    ContactDown,
    ContactUp,
    Ended,
    HoldPlan,
    NoiseReleased,
    Refused,
    Released,
    ReleaseJob,
    Started,
    StartJob,
    StoppedAll,
    perform,
)
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema.pattern import SineCarrier

DEVICE = DeviceProfile.default()
STROKE = TouchPattern.model_validate(
    {"path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]}, "speed_cm_s": 40.0}
)
VOID, PLAYED = 1, 2
"""The integers of two jobs started on the audio side by hand."""


def _classes(union: object) -> set[type]:
    return set(getattr(union, "__args__", ()))


def test_every_command_has_exactly_one_applier_and_is_a_frozen_slotted_dataclass() -> None:
    commands = _classes(messages.Command)
    assert commands == set(APPLIERS)
    for kind in commands | _classes(messages.Event):
        assert dataclasses.is_dataclass(kind), kind
        params = kind.__dataclass_params__  # type: ignore[attr-defined]
        assert params.frozen and "__slots__" in vars(kind), kind


def test_messages_and_events_cross_a_pickle_unchanged() -> None:
    unit = np.linspace(0.0, 1.0, DEVICE.channels, dtype=np.float32)
    down = ContactDown(5, 1.0, 2.0, unit, 0.5, SineCarrier(), "power", None, 96, 3, 7)
    back = pickle.loads(pickle.dumps(down, protocol=pickle.HIGHEST_PROTOCOL))
    assert (back.contact, back.slot, back.generation, back.frame) == (5, 3, 7, 96)
    np.testing.assert_array_equal(back.unit_gains, unit)
    for event in (
        Started("contact", 5, 5, False, 1.0, 2.0, 0.5),
        Released("job", 1, 7, 9),
        Ended("job", 1, 9),
        Cancelled("job", 1, 3),
        StoppedAll(11),
        NoiseReleased((20.0, 400.0, 1, 48000)),
        Refused("plan", 1, "not handed over"),
    ):
        assert pickle.loads(pickle.dumps(event)) == event


@pytest.mark.parametrize(
    "message",
    [
        StartJob(3, 4, None),
        ReleaseJob(3, 96, 240),
        Started("job", 5, 5, False),
        Ended("job", 1, 9),
        StoppedAll(11),
    ],
    ids=lambda message: type(message).__name__,
)
def test_a_message_pickles_as_its_class_and_values_not_a_state_to_set(message: object) -> None:
    """A slotted dataclass's own state is set field by field after it is made (BUILD);
    these are rebuilt by their ``__init__`` from their values in one step."""
    frame = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    opcodes = {opcode.name for opcode, _, _ in pickletools.genops(frame)}
    assert "BUILD" not in opcodes and "REDUCE" in opcodes, opcodes
    assert pickle.loads(frame) == message


def test_a_command_is_applied_through_the_table_and_a_void_one_plays_nothing() -> None:
    sink = CaptureSink(DEVICE)
    engine = Engine(DEVICE, sink, prerender_max_s=0.0)
    engine.core.start()  # the core alone: no housekeeping thread takes the events
    try:
        state = AudioState(engine.core)
        resolved = plan(STROKE, DEVICE)
        perform(state, HoldPlan(1, resolved, None), void=True)
        perform(state, StartJob(VOID, 1, 0), void=True)
        perform(state, StartJob(PLAYED, 1, 0))
        perform(state, ReleaseJob(PLAYED, 4 * DEVICE.block_frames, None))
        sink.pull(40)
        events = engine.core.events() + state.reports
    finally:
        engine.close()
    assert Cancelled("job", VOID, 0) in events
    started = [e for e in events if isinstance(e, Started)]
    assert [(e.key, e.frame) for e in started] == [(PLAYED, 0)]
    released = [e for e in events if isinstance(e, Released)]
    assert [(e.key, e.frame) for e in released] == [(PLAYED, 4 * DEVICE.block_frames)]


def test_the_audio_side_refuses_a_plan_it_was_not_handed() -> None:
    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        state = AudioState(engine.core)
        perform(state, StartJob(1, 4242, None))
    assert state.refused == 1
    assert [type(e) for e in state.reports] == [Refused, Cancelled]
    assert state.reports[0].what == "plan"


def test_an_up_for_a_contact_that_is_not_sounding_is_ignored() -> None:
    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        state = AudioState(engine.core)
        perform(state, ContactUp((99,), None, None))
        assert engine.core.queue.depth == 0 and not state.reports


@pytest.mark.parametrize("command", sorted(APPLIERS, key=lambda kind: kind.__name__))
def test_every_applier_says_it_runs_in_real_time_or_not(command: type) -> None:
    doc = APPLIERS[command].__doc__ or ""
    assert "real time" in doc.lower(), command


def test_the_two_engines_are_one_front_and_add_only_their_constructor_and_accessors() -> None:
    from phantomtouch.engine import EngineFront, ProcessEngine

    assert Engine.__mro__[1] is EngineFront and ProcessEngine.__mro__[1] is EngineFront
    own = {
        name
        for kind in (Engine, ProcessEngine)
        for name, value in vars(kind).items()
        if callable(value) and not name.startswith("__")
    }
    assert own == set()  # every method is the front's; properties only name the audio side
    assert {"__init__"} <= set(vars(Engine)) and {"__init__"} <= set(vars(ProcessEngine))


def test_a_touchdown_sounds_with_the_gains_the_front_computed_not_recomputed() -> None:
    channel = 5
    unit = np.zeros(DEVICE.channels, dtype=np.float32)
    unit[channel] = 1.0  # no position of the layout has these gains: the board must not redo them
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, contact=None) as engine:
        state = AudioState(engine.core)
        perform(state, ContactDown(1, 0.0, 0.0, unit, 0.25, SineCarrier(), "power", None, 0))
        recording = sink.pull(20)
    silent = [k for k in range(DEVICE.channels) if k != channel]
    assert not np.any(recording[:, silent])
    assert np.max(np.abs(recording[:, channel])) > 0.0
