"""Contacts that arrive over NATS reach the engine's output, and only well-formed ones."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import numpy as np
import pytest
from pydantic import ValidationError

from phantomtouch.engine import ContactSettings, Engine
from phantomtouch.errors import ProtocolError
from phantomtouch.fleet.remote_contacts import PRINCIPAL, Principals, RemoteContacts
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, policy_table
from phantomtouch.service.errors import QuotaError, TooLargeError
from phantomtouch.service.settings import Settings

DEVICE = DeviceProfile.default()
WATCHDOG_S = 0.5


RELEASED: list[tuple[str, tuple[str, ...], str]] = []
"""What ``on_released`` was told: owner, contacts, reason."""


@pytest.fixture
def captured() -> Iterator[tuple[RemoteContacts, CaptureSink]]:
    """The node's remote contacts over an admission whose fleet row has a short deadline, two
    contacts per owner and 1 KiB messages, on an engine pulled by hand; the cluster is
    taken as closed (the principals gateways name are believed)."""
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        table = policy_table(Settings())
        table["fleet"] = table["fleet"].replace(
            deadline_s=WATCHDOG_S, contacts_per_owner=2, max_message_bytes=1024
        )
        RELEASED.clear()
        contacts = RemoteContacts(
            Admission(engine, table),
            principals=Principals(named=True),
            on_released=lambda owner, held, reason: RELEASED.append((owner, held, reason)),
        )
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
    assert contacts.count() == 1 and RELEASED == []
    engine.release_expired(now_s=time.monotonic() + WATCHDOG_S * 1.01)
    assert contacts.count() == 0
    assert RELEASED == [("gw-1", ("f",), "watchdog")]
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


def test_the_principal_a_gateway_names_is_the_owners(
    captured: tuple[RemoteContacts, CaptureSink],
) -> None:
    contacts, _ = captured
    down = {"type": "down", "contact": "f", "x_cm": 1.9, "y_cm": 7.2}
    contacts.handle(_message(**down, principal="fleet:10.0.0.7"))
    contacts.handle(json.dumps({**down, "owner": "gw-2"}).encode())
    owners = {h.source: h.principal for h in contacts.admission.handles("fleet")}
    assert owners == {"gw-1": "fleet:10.0.0.7", "gw-2": PRINCIPAL}
    assert contacts.admission.engine.contacts_of("fleet:10.0.0.7/gw-1") == ["f"]


@pytest.mark.parametrize("named", [True, False], ids=["closed cluster", "open cluster"])
def test_a_crowd_of_one_client_host_takes_nothing_from_another(named: bool) -> None:
    """Every engine contact slot is held by owners of one client host, then another host's
    owner puts a contact down, then the crowd's host opens four more owners, each with a
    down. Believing the principals the gateway names (a closed cluster), the other host's
    contact stays: shares go first among principals, and the crowd passes its own slots
    round. As one principal (an open cluster) the newcomers take every slot in turn, the
    other host's with them."""
    sink = CaptureSink(DEVICE)
    contact = ContactSettings(max_contacts=4)
    with Engine(DEVICE, sink, contact=contact) as engine:
        contacts = RemoteContacts(
            Admission(engine, policy_table(Settings())), principals=Principals(named=named)
        )
        down = {"type": "down", "contact": "f", "x_cm": 1.9, "y_cm": 2.4}

        def crowd(k: int) -> None:
            owner = {"owner": f"gw-{k}", "principal": "fleet:10.0.0.66"}
            contacts.handle(json.dumps({**down, **owner}).encode())

        for k in range(4):
            crowd(k)
        other = {"owner": "gw-other", "principal": "fleet:10.0.0.7"}
        assert contacts.handle(json.dumps({**down, **other}).encode()) == "down"
        for k in range(4, 8):
            crowd(k)
        other_owner = ("fleet:10.0.0.7" if named else PRINCIPAL) + "/gw-other"
        assert engine.contacts_of(other_owner) == (["f"] if named else [])
        assert contacts.count() == 4
        contacts.close()


def test_on_an_open_cluster_every_publisher_is_one_principal() -> None:
    open_cluster = Principals(named=False)
    assert open_cluster.of("fleet:10.0.0.7") == PRINCIPAL
    assert open_cluster.of(None) == PRINCIPAL
    assert Principals(named=True).of(None) == PRINCIPAL


@pytest.mark.parametrize(
    "claimed", ["ws:127.0.0.1", "osc:10.0.0.7", "fleet:a/b", "fleet:" + "x" * 40, 7, ""]
)
def test_a_principal_a_gateway_does_not_make_is_refused(claimed: object) -> None:
    with pytest.raises(ProtocolError, match="principal="):
        Principals(named=True).of(claimed)
