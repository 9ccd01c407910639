"""Parsing WebSocket frames: every malformed frame becomes an answer, never a crash."""

from __future__ import annotations

import pytest

from phantomtouch.service.models import PresetTouch
from phantomtouch.service.ws_messages import Down, MessageError, Move, Play, Subscribe, parse


def test_move_and_down() -> None:
    move = parse('{"type": "move", "contact": "L", "x_cm": 1.5, "y_cm": 7}')
    assert move == Move(type="move", contact="L", x_cm=1.5, y_cm=7.0)
    down = parse(
        '{"type": "down", "contact": "L", "x_cm": 1, "y_cm": 2, "id": 7, '
        '"carrier": {"kind": "noise"}}'
    )
    assert isinstance(down, Down)
    assert down.id == 7
    assert down.carrier is not None and down.carrier.kind == "noise"


def test_play_carries_a_touch_request() -> None:
    play = parse('{"type": "play", "id": "a", "preset": "vr/tap", "start_in_ms": 10}')
    assert isinstance(play, Play)
    assert isinstance(play.request, PresetTouch)
    assert play.request.start_in_ms == 10.0


@pytest.mark.parametrize(
    ("text", "code", "field", "message_id"),
    [
        ("{nope", "invalid_json", "body", None),
        ("[1]", "invalid", "body", None),
        ('{"id": 3}', "invalid", "type", 3),
        ('{"type": "dance", "id": "x"}', "unknown_type", "type", "x"),
        ('{"type": "move", "contact": "L", "x_cm": "1", "y_cm": 2, "id": 4}', "invalid", "x_cm", 4),
        ('{"type": "move", "contact": "", "x_cm": 1, "y_cm": 2}', "invalid", "contact", None),
        (
            '{"type": "down", "contact": "L", "x_cm": 1, "y_cm": 2, "intensity": 2}',
            "invalid",
            "intensity",
            None,
        ),
        ('{"type": "subscribe", "rate_hz": 500}', "invalid", "rate_hz", None),
        ('{"type": "ping", "extra": 1}', "invalid", "extra", None),
        (
            '{"type": "play", "preset": "vr/tap", "start_in_ms": -1, "id": 9}',
            "invalid",
            "start_in_ms",
            9,
        ),
    ],
)
def test_malformed_frames(text: str, code: str, field: str, message_id: object) -> None:
    with pytest.raises(MessageError) as info:
        parse(text)
    problem = info.value.problem
    assert problem.code == code
    assert problem.fields[0]["field"] == field
    assert info.value.message_id == message_id


def test_subscribe_zero_stops() -> None:
    assert parse('{"type": "subscribe", "rate_hz": 0}') == Subscribe(type="subscribe", rate_hz=0)
