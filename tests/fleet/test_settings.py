"""Fleet and gateway settings, scope tokens and stop scopes refuse nonsense by name."""

from __future__ import annotations

import re

import pytest

from phantomtouch.errors import ParameterError
from phantomtouch.fleet.auth import Grants, GrantSpec
from phantomtouch.fleet.gateway_settings import GatewaySettings
from phantomtouch.fleet.records import StopScope
from phantomtouch.fleet.settings import FleetSettings


def test_servers_are_split_and_checked() -> None:
    settings = FleetSettings(servers="nats://127.0.0.1:4222, nats://127.0.0.1:4223")  # type: ignore[arg-type]
    assert settings.servers == ["nats://127.0.0.1:4222", "nats://127.0.0.1:4223"]
    with pytest.raises(ValueError, match="nats://HOST:PORT"):
        FleetSettings(servers=["http://127.0.0.1:4222"])


@pytest.mark.parametrize("armband", ["a.b", "a b", "*", ">", "", "x" * 65])
def test_an_armband_id_is_one_subject_token(armband: str) -> None:
    with pytest.raises(ValueError, match="armband"):
        FleetSettings(armband=armband)


def test_the_ttl_outlasts_two_heartbeats() -> None:
    with pytest.raises(
        ValueError, match=re.escape("ttl_s=1.0 must be at least twice heartbeat_s=1.0")
    ):
        FleetSettings(heartbeat_s=1.0, ttl_s=1.0)


def test_a_gateway_off_loopback_needs_tokens() -> None:
    with pytest.raises(ValueError, match="needs tokens"):
        GatewaySettings(host="0.0.0.0")
    assert GatewaySettings(host="0.0.0.0", token="a-token-of-16-chars").host == "0.0.0.0"


def test_a_grant_allows_its_armbands_only() -> None:
    grants = Grants(
        {"alice-token-0123456789": GrantSpec(player="alice", armbands=["a1"])},
        admin_token="admin-token-0123456789",
    )
    alice = grants.grant("alice-token-0123456789")
    assert alice is not None and alice.allows("a1") and not alice.allows("a2")
    admin = grants.grant("admin-token-0123456789")
    assert admin is not None and admin.allows("a2")
    assert grants.grant("alice-token-012345678") is None
    assert grants.grant(None) is None
    with pytest.raises(ValueError, match="under 16 characters"):
        Grants({"short": GrantSpec(player="bob", armbands="*")}, admin_token=None)


@pytest.mark.parametrize(
    ("scope", "message"),
    [
        (StopScope(scope="site"), "site=null: required with scope='site'"),
        (StopScope(scope="armband"), "armband=null: required with scope='armband'"),
        (StopScope(scope="all", site="x"), "site='x': not allowed with scope='all'"),
        (StopScope(scope="site", site="x", armband="y"), "armband='y': not allowed"),
    ],
)
def test_a_stop_scope_names_what_it_lacks(scope: StopScope, message: str) -> None:
    with pytest.raises(ParameterError, match=re.escape(message)):
        scope.check()
