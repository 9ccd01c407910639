"""The fleet's part of the command line.

``phantomtouch serve --fleet nats://HOST:4222 --armband ID [--site NAME]`` joins the
service to a fleet as an armband node; ``phantomtouch gateway --fleet nats://...`` runs a
gateway; ``phantomtouch fleet-config`` writes a closed NATS configuration for them. NATS
credentials come from the environment (docs/fleet.md), never from a flag. Both refuse a
NATS server open to anonymous publishers, or a cluster whose route ports admit a server
without credentials, unless told they may (:mod:`phantomtouch.fleet.openness`,
:mod:`phantomtouch.fleet.route_probe`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager
from typing import TYPE_CHECKING, Any

from phantomtouch.errors import ParameterError, PhantomTouchError, install_hint

if TYPE_CHECKING:
    from phantomtouch.fleet.settings import FleetSettings
    from phantomtouch.service.running import Service


ROUTES_HELP = (
    "the cluster's NATS route ports, comma-separated (HOST:6222): checked to admit no server "
    "without credentials"
)
OPEN_NATS_HELP = (
    "a NATS server that lets anonymous clients publish on the armbands' subjects (anyone "
    "reaching it can play on every armband)"
)
"""What ``--fleet-insecure`` and ``--insecure-nats`` let the command run on."""


def _routes(given: str | None) -> list[str]:
    return [part.strip() for part in (given or "").split(",") if part.strip()]


def _require_closed(servers: list[str], routes: list[str], flag: str, command: str) -> None:
    """Refuse NATS open to anonymous clients or servers (:mod:`~phantomtouch.fleet.openness`,
    :mod:`~phantomtouch.fleet.route_probe`); say in one line what cannot be told."""
    from phantomtouch.fleet.openness import require_closed
    from phantomtouch.fleet.route_probe import check_routes

    require_closed(servers, flag)
    note = check_routes(servers, routes, flag)
    if note is not None:
        print(f"phantomtouch {command}: {note}", file=sys.stderr)


def add_serve_options(serve: argparse.ArgumentParser) -> None:
    """``--fleet``, ``--armband`` and ``--site`` of ``phantomtouch serve``."""
    serve.add_argument(
        "--fleet", help="join a fleet: NATS server URL(s), comma-separated (nats://HOST:4222)"
    )
    serve.add_argument("--armband", help="this armband's id in the fleet (with --fleet)")
    serve.add_argument("--site", help="this armband's site in the fleet (default: 'default')")
    serve.add_argument("--fleet-routes", help=ROUTES_HELP)
    serve.add_argument(
        "--fleet-insecure",
        action="store_true",
        help=f"join even {OPEN_NATS_HELP}",
    )


def _fleet_settings(args: argparse.Namespace, **more: Any) -> FleetSettings:
    from pydantic import ValidationError

    from phantomtouch.fleet.settings import FleetSettings
    from phantomtouch.schema import describe_validation_error

    options = {"servers": args.fleet, **more}
    try:
        return FleetSettings(**{k: v for k, v in options.items() if v is not None})
    except ValidationError as exc:
        raise ParameterError(f"invalid fleet settings: {describe_validation_error(exc)}") from exc


def _require_nats() -> None:
    import importlib.util

    if importlib.util.find_spec("nats") is None:
        raise PhantomTouchError(
            f"nats is not installed: this needs the fleet extra; {install_hint('fleet')}"
        )


def attachment(
    args: argparse.Namespace,
) -> Callable[[Service], AbstractAsyncContextManager[None]] | None:
    """What ``serve`` attaches to the service: the armband node, or None without ``--fleet``."""
    if args.fleet is None:
        if args.armband is not None or args.site is not None:
            raise ParameterError("--armband and --site need --fleet nats://HOST:4222")
        if args.fleet_insecure:
            raise ParameterError("--fleet-insecure needs --fleet nats://HOST:4222")
        if args.fleet_routes is not None:
            raise ParameterError("--fleet-routes needs --fleet nats://HOST:4222")
        return None
    if args.armband is None:
        raise ParameterError("--fleet needs --armband ID: the id this armband has in the fleet")
    _require_nats()
    from phantomtouch.fleet.node import attach

    settings = _fleet_settings(args, armband=args.armband, site=args.site)
    if not args.fleet_insecure:
        _require_closed(settings.servers, _routes(args.fleet_routes), "--fleet-insecure", "serve")
    print(
        f"phantomtouch {args.command}: armband {settings.armband!r} of site {settings.site!r} "
        f"on the fleet at {', '.join(settings.servers)}"
    )
    return attach(settings, closed_cluster=not args.fleet_insecure)


def _cmd_gateway(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from phantomtouch.schema import describe_validation_error

    _require_nats()
    from phantomtouch.fleet.gateway import create_gateway
    from phantomtouch.fleet.gateway_settings import GatewaySettings
    from phantomtouch.service.listen import check_port_free, run_http

    options = {"host": args.host, "port": args.port, "token": args.token}
    try:
        settings = GatewaySettings(**{k: v for k, v in options.items() if v is not None})
    except ValidationError as exc:
        raise ParameterError(f"invalid settings: {describe_validation_error(exc)}") from exc
    fleet = _fleet_settings(args)
    check_port_free(settings.host, settings.port)
    if not args.insecure_nats:
        _require_closed(fleet.servers, _routes(args.fleet_routes), "--insecure-nats", "gateway")
    print(
        f"phantomtouch gateway: http://{settings.host}:{settings.port} for the fleet at "
        f"{', '.join(fleet.servers)}",
        file=sys.stdout,
        flush=True,
    )
    run_http(create_gateway(settings, fleet), settings)
    return 0


def register(sub: Any) -> None:
    """Add ``phantomtouch gateway`` to the subcommands ``sub``."""
    gateway = sub.add_parser("gateway", help="run a REST and WebSocket gateway of a fleet")
    gateway.add_argument(
        "--fleet", required=True, help="NATS server URL(s), comma-separated (nats://HOST:4222)"
    )
    gateway.add_argument("--host", help="address to bind (default 127.0.0.1; others need tokens)")
    gateway.add_argument("--port", type=int, help="TCP port (default 8100)")
    gateway.add_argument(
        "--token", help="a token of every armband (also PHANTOMTOUCH_GATEWAY_TOKEN)"
    )
    gateway.add_argument("--fleet-routes", help=ROUTES_HELP)
    gateway.add_argument(
        "--insecure-nats",
        action="store_true",
        help=f"run even on {OPEN_NATS_HELP}",
    )
    gateway.set_defaults(func=_cmd_gateway)
    config = sub.add_parser(
        "fleet-config",
        help="write a closed NATS configuration: a user per armband node and per gateway",
    )
    config.add_argument(
        "--armband",
        action="append",
        default=[],
        metavar="ID:SITE",
        help="an armband node's id and site (repeat for each)",
    )
    config.add_argument(
        "--gateway", action="append", default=[], metavar="NAME", help="a gateway (repeat)"
    )
    config.add_argument("--out", required=True, help="folder for authorization.conf and USER.env")
    config.set_defaults(func=_cmd_fleet_config)


def _cmd_fleet_config(args: argparse.Namespace) -> int:
    from pathlib import Path

    from phantomtouch.fleet.nats_config import RouteUser, plan, write

    armbands = []
    for given in args.armband:
        armband, _, site = given.partition(":")
        armbands.append((armband, site or "default"))
    users = plan(armbands, args.gateway)
    for path in write(Path(args.out), users, RouteUser.new()):
        print(f"phantomtouch fleet-config: wrote {path}")
    print(
        "include authorization.conf in every NATS server's configuration and "
        "route-authorization.conf in its cluster block, with route URLs "
        "nats-route://USER:PASSWORD@HOST:PORT from route.env; start each node and gateway "
        "with the variables of its USER.env (docs/fleet.md)"
    )
    return 0
