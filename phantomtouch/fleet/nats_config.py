"""A closed NATS configuration for a fleet: one user per armband node and per gateway.

``phantomtouch fleet-config`` writes it (:func:`write`): ``authorization.conf``, to be
``include``d in every server's configuration, and one ``USER.env`` per user holding the
``PHANTOMTOUCH_FLEET_USER`` and ``PHANTOMTOUCH_FLEET_PASSWORD`` that user starts with
(both files readable by their owner only). With it NATS itself enforces what each may do:

- nobody connects without a user (no anonymous client);
- a node subscribes only to its own armband's subjects, its site's stop and the fleet's
  stop, answers the requests it receives (``allow_responses``), publishes only its own
  armband's release notices, and of the registry may write only its own key; it cannot
  publish a touch, a contact or a stop anywhere;
- a gateway publishes on ``phantomtouch.>`` (what it serves: touches, contacts, stops and
  clock requests of every armband), hears every armband's release notices, and reads the
  registry; it cannot write in it.

The cluster's route ports are closed too: ``route-authorization.conf``, to be ``include``d
in every server's ``cluster { }`` block, admits only servers that give the route user
and password of ``route.env`` in their route URLs (``nats-route://USER:PASSWORD@HOST:PORT``),
so a server started by anyone else cannot join the cluster and publish on the armbands'
subjects past every client permission.

Both reach the registry's JetStream API (stream info and creation, consumers for their
watches) of the registry's stream only, and receive replies and watch deliveries on an
inbox prefix of their own (``_INBOX_USER``), so no user reads another's replies.
"""

from __future__ import annotations

import json
import secrets
from dataclasses import dataclass
from pathlib import Path

from phantomtouch.errors import ParameterError
from phantomtouch.fleet import subjects
from phantomtouch.fleet.subjects import REGISTRY_BUCKET

STREAM = f"KV_{REGISTRY_BUCKET}"
REGISTRY_API = [
    f"$JS.API.STREAM.INFO.{STREAM}",
    f"$JS.API.STREAM.CREATE.{STREAM}",
    f"$JS.API.CONSUMER.CREATE.{STREAM}",
    f"$JS.API.CONSUMER.CREATE.{STREAM}.>",
    f"$JS.API.CONSUMER.INFO.{STREAM}.>",
    f"$JS.API.CONSUMER.DELETE.{STREAM}.>",
    f"$JS.API.DIRECT.GET.{STREAM}.>",
    f"$JS.API.STREAM.MSG.GET.{STREAM}",
    f"$JS.FC.{STREAM}.>",
]
"""The JetStream API subjects of the registry's stream that nodes and gateways use."""


def inbox_prefix(user: str) -> str:
    """The reply inbox prefix of ``user``'s connections."""
    return f"_INBOX_{user}"


@dataclass(frozen=True)
class FleetUser:
    """One NATS user: an armband node (``armband`` and ``site`` set) or a gateway."""

    name: str
    password: str
    armband: str | None = None
    site: str | None = None

    def permissions(self) -> dict[str, object]:
        """The user's nats-server ``permissions`` map."""
        inbox = f"{inbox_prefix(self.name)}.>"
        if self.armband is None:
            return {
                "publish": {"allow": ["phantomtouch.>", *REGISTRY_API]},
                "subscribe": {"allow": [f"{subjects.PREFIX}.released.>", inbox]},
            }
        assert self.site is not None
        return {
            "publish": {
                "allow": [
                    f"$KV.{REGISTRY_BUCKET}.{self.armband}",
                    f"{subjects.PREFIX}.released.{self.armband}.*",
                    *REGISTRY_API,
                ],
            },
            "subscribe": {
                "allow": [
                    f"phantomtouch.armband.{self.armband}.>",
                    subjects.stop_site(self.site),
                    subjects.STOP_ALL,
                    inbox,
                ]
            },
            "allow_responses": True,
        }

    def env(self) -> str:
        """The environment this user's node or gateway starts with."""
        return f"PHANTOMTOUCH_FLEET_USER={self.name}\nPHANTOMTOUCH_FLEET_PASSWORD={self.password}\n"


@dataclass(frozen=True)
class RouteUser:
    """The one user servers of the cluster give each other on their route ports."""

    password: str
    name: str = "route"

    @classmethod
    def new(cls) -> RouteUser:
        return cls(secrets.token_urlsafe(24))

    def authorization(self) -> str:
        """The ``authorization`` of a server's ``cluster { }`` block."""
        entry = {"user": self.name, "password": self.password, "timeout": 2}
        return "authorization: " + json.dumps(entry) + "\n"

    def route_url(self, host: str, port: int) -> str:
        """A route URL to another server of the cluster, with the route credentials."""
        return f"nats-route://{self.name}:{self.password}@{host}:{port}"

    def env(self) -> str:
        """What a script writing the servers' configurations builds route URLs from."""
        return f"PHANTOMTOUCH_ROUTE_USER={self.name}\nPHANTOMTOUCH_ROUTE_PASSWORD={self.password}\n"


def plan(armbands: list[tuple[str, str]], gateways: list[str]) -> list[FleetUser]:
    """A user per armband (``(id, site)``; user name = the id) and per gateway, each with
    a fresh random password.

    Raises
    ------
    ParameterError
        An id, site or gateway name is not a subject token, or a name repeats.
    """
    users: list[FleetUser] = []
    for armband, site in armbands:
        subjects.check_name("armband", armband)
        subjects.check_name("site", site)
        users.append(FleetUser(armband, secrets.token_urlsafe(24), armband=armband, site=site))
    for gateway in gateways:
        subjects.check_name("gateway", gateway)
        users.append(FleetUser(gateway, secrets.token_urlsafe(24)))
    names = [user.name for user in users]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ParameterError(
            f"names={repeated!r}: every armband and gateway needs a name of its own"
        )
    if not users:
        raise ParameterError("give at least one --armband ID:SITE or --gateway NAME")
    return users


def authorization(users: list[FleetUser]) -> str:
    """The nats-server ``authorization`` block for ``users`` (JSON is valid NATS config)."""
    entries = [
        {"user": user.name, "password": user.password, "permissions": user.permissions()}
        for user in users
    ]
    return "authorization: " + json.dumps({"users": entries}, indent=2) + "\n"


def write(folder: Path, users: list[FleetUser], route: RouteUser) -> list[Path]:
    """Write ``authorization.conf``, one ``USER.env`` per user, ``route-authorization.conf``
    and ``route.env`` into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in [
        ("authorization.conf", authorization(users)),
        *((f"{user.name}.env", user.env()) for user in users),
        ("route-authorization.conf", route.authorization()),
        ("route.env", route.env()),
    ]:
        path = folder / name
        path.touch(mode=0o600)
        path.chmod(0o600)
        path.write_text(text)
        written.append(path)
    return written
