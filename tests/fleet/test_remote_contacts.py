"""Contacts that arrive over NATS reach the engine's output, and only well-formed ones."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import numpy as np
import pytest
from pydantic import ValidationError

from phantomtouch.engine import CaptureSink, Engine
from phantomtouch.errors import ProtocolError
from phantomtouch.fleet.remote_contacts import RemoteContacts
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, policy_table
from phantomtouch.service.errors import QuotaError, TooLargeError
from phantomtouch.service.settings import Settings

DEVICE = DeviceProfile.default()
WATCHDOG_S = 0.5


SILENT: list[str] = []


@pytest.fixture
def captured() -> Iterator[tuple[RemoteContacts, CaptureSink]]:
    """The node's remote contacts over an admission whose fleet row has a short deadline, two
    contacts per owner and 1 KiB messages, on an engine pulled by hand."""
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        table = policy_table(Settings())
        table["fleet"] = table["fleet"].replace(
            deadline_s=WATCHDOG_S, contacts_per_owner=2, max_message_bytes=1024
        )
        SILENT.clear()
        contacts = RemoteContacts(Admission(engine, table), on_silent=SILENT.append)
        yield contacts, sink
        contacts.close()


def _message(**fields: object) -> bytes:
    return json.dumps({"owner": "gw-1", **fields}).encode()


def test_a_remote_down_drives_the_actuator_under_it_only(
    captured: tuple[RemoteContacts, CaptureSink],
) -> None:
    contacts, sink = captured
    assert contacts.handle(_message(type="down", contact="f", x_cm=0.0, y_cm=4.8)) == "down"
    recording = sink.pull(8)
    assert np.any(recording[:, 1])  # actuator 2 sits at (0, 4.8) cm on channel 2
    assert not np.any(np.delete(recording, 1, axis=1))


def test_a_silent_owner_is_released_by_its_deadline(
    captured: tuple[RemoteContacts, CaptureSink],
) -> None:
    contacts, sink = captured
    engine = contacts.admission.engine
    contacts.handle(_message(type="down", contact="f", x_cm=1.9, y_cm=7.2))
    contacts.handle(_message(type="ping"))  # a message of the owner's own renews it
    heard_s = time.monotonic()
    engine.release_expired(now_s=heard_s + WATCHDOG_S / 2)
    assert contacts.count() == 1 and SILENT == []
    engine.release_expired(now_s=time.monotonic() + WATCHDOG_S * 1.01)
    assert contacts.count() == 0
    assert SILENT == ["gw-1"]
    sink.pull(40)  # the release ramp
    assert not np.any(sink.pull(2))


@pytest.mark.parametrize(
    ("data", "error"),
    [
        (b"not json", ProtocolError),
        (b"[1, 2]", ProtocolError),
        (
            json.dumps({"type": "down", "contact": "f", "x_cm": 1, "y_cm": 1}).encode(),
            ProtocolError,
        ),
        (_message(type="move", contact="f", x_cm=1.0, y_cm=1.0), ProtocolError),
        (_message(type="down", contact="f", x_cm="far", y_cm=1.0), ValidationError),
        (_message(type="down", contact="f", x_cm=1.0, y_cm=1.0, speed=3), ValidationError),
        (_message(type="teleport"), ProtocolError),
        (_message(type="down", contact="f", x_cm=1.0, y_cm=1.0, pad="x" * 2000), TooLargeError),
    ],
)
def test_a_bad_message_is_refused_and_plays_nothing(
    captured: tuple[RemoteContacts, CaptureSink], data: bytes, error: type[Exception]
) -> None:
    contacts, sink = captured
    with pytest.raises(error):
        contacts.handle(data)
    assert not np.any(sink.pull(4))


def test_the_contact_quota_holds_per_owner(captured: tuple[RemoteContacts, CaptureSink]) -> None:
    contacts, _ = captured
    for contact in ("a", "b"):
        contacts.handle(_message(type="down", contact=contact, x_cm=1.0, y_cm=1.0))
    with pytest.raises(QuotaError, match="fleet contacts per owner=2"):
        contacts.handle(_message(type="down", contact="c", x_cm=1.0, y_cm=1.0))
    other = json.dumps({"owner": "gw-2", "type": "down", "contact": "c", "x_cm": 1, "y_cm": 1})
    assert contacts.handle(other.encode()) == "down"
    assert contacts.count() == 3
