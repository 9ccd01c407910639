"""``phantomtouch serve``, ``phantomtouch osc`` and ``phantomtouch gateway``: the service
commands, their flags and the checks made before anything opens."""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from typing import TYPE_CHECKING

from phantomtouch.errors import DeviceError, ParameterError, PhantomTouchError, install_hint
from phantomtouch.fleet import cli as fleet_cli
from phantomtouch.osc.command import add_osc_command
from phantomtouch.output.devices import release_portaudio
from phantomtouch.schema import describe_validation_error

if TYPE_CHECKING:
    from phantomtouch.service.running import Attachment
    from phantomtouch.service.settings import Settings

EXIT_FAILURE = 1
"""A runtime failure (2 is a usage error)."""


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ImportError:
        return False


def _require(extra: str, *modules: str) -> None:
    """Refuse to go on without an extra's modules, naming the extra to install."""
    missing = [m for m in modules if not _importable(m)]
    if missing:
        raise PhantomTouchError(
            f"{missing[0]} is not installed: this needs the {extra} extra; {install_hint(extra)}"
        )


def _cmd_serve(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    _require("server", "fastapi", "uvicorn", "pydantic_settings")
    from phantomtouch.server.serve import check_device_profile, check_library, check_output, serve
    from phantomtouch.service.listen import check_port_free
    from phantomtouch.service.settings import Settings

    if args.output != "null" and not _importable("sounddevice"):
        print(
            f"phantomtouch {args.command}: sounddevice is not installed ({install_hint('audio')}): "
            "playing to the null output, no sound card",
            file=sys.stderr,
        )

    options = {
        "host": args.host,
        "port": args.port,
        "device_profile": args.device,
        "output_device": args.output,
        "db_path": args.db,
        "token": args.token,
        "osc_listen": args.osc,
        "osc_map": args.osc_map,
        "wasapi_exclusive": args.exclusive or None,
        "period_frames": args.period,
        "wearer": args.wearer,
        "wearer_band": args.wearer_band,
        "bhaptics_listen": args.bhaptics,
        "bhaptics_sdk2_listen": args.bhaptics_sdk2,
        "bhaptics_map": args.bhaptics_map,
    }
    if args.osc is not None:
        _require("osc", "pythonosc")
    try:
        settings = Settings(**{k: v for k, v in options.items() if v is not None})
    except ValidationError as exc:
        raise ParameterError(f"invalid settings: {describe_validation_error(exc)}") from exc
    check_device_profile(settings)
    check_output(settings)
    release_portaudio()  # the engine process plays: no idle client of this one in JACK's graph
    fleet = fleet_cli.attachment(args)
    try:
        check_library(settings)
    except DeviceError as exc:
        print(f"phantomtouch {args.command}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    check_port_free(settings.host, settings.port)
    if settings.osc_address is not None:
        from phantomtouch.osc.bridge import open_socket
        from phantomtouch.osc.mapping import load_map
        from phantomtouch.schema import DeviceProfile

        profile = settings.device_profile
        load_map(
            settings.osc_map, DeviceProfile.load(profile) if profile else DeviceProfile.default()
        )
        open_socket(*settings.osc_address).close()
    if settings.bhaptics_address is not None:
        from phantomtouch.clips.tact_map import ArmMap

        if settings.bhaptics_map is not None:
            ArmMap.load(settings.bhaptics_map)
        check_port_free(*settings.bhaptics_address)
    if settings.bhaptics_sdk2_listen is not None and settings.bhaptics_sdk2_address:
        check_port_free(*settings.bhaptics_sdk2_address)
    print(
        f"phantomtouch {args.command}: http://{settings.host}:{settings.port} (API docs at "
        f"/docs); library {settings.db_path} (--db FILE for another)"
    )
    if settings.bhaptics_address is not None:
        host, port = settings.bhaptics_address
        print(f"phantomtouch {args.command}: bHaptics stand-in on ws://{host}:{port}/v2/feedbacks")
    if settings.bhaptics_sdk2_address is not None:
        host, port = settings.bhaptics_sdk2_address
        print(f"phantomtouch {args.command}: bHaptics SDK2 on wss://{host}:{port}/v3/feedback")
    serve(settings, attach=_attachments(settings, fleet))
    return 0


def _attachments(settings: Settings, fleet: Attachment | None) -> list[Attachment]:
    """What the running service is joined to, in the order it is entered: the OSC bridge
    (``osc_listen`` set), the bHaptics stand-in in its own thread (``bhaptics_listen`` set),
    then the armband node (``--fleet``)."""
    attachments: list[Attachment] = []
    if settings.osc_address is not None:
        from phantomtouch.osc.service_link import attach

        attachments.append(attach)
    if settings.bhaptics_address is not None:
        from phantomtouch.bhaptics.own_loop import attach as attach_bhaptics

        attachments.append(attach_bhaptics)
    if settings.bhaptics_sdk2_address is not None:
        from phantomtouch.bhaptics.sdk2.listener import attach as attach_sdk2

        attachments.append(attach_sdk2)
    if fleet is not None:
        attachments.append(fleet)
    return attachments


def _serve_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", help="address to bind (default 127.0.0.1; others need --token)")
    parser.add_argument("--port", type=int, help="TCP port (default 8000)")
    parser.add_argument("--device", help="device profile (TOML or JSON); default: the paper's")
    parser.add_argument(
        "--output",
        help="sound-card output: a part of its name, its index or HOSTAPI:NAME (e.g. "
        "'ASIO:Focusrite', 'WASAPI:Speakers'; see 'phantomtouch devices'), 'null', or "
        "'capture:FILE.wav' (records what plays; written at exit) (default: first that fits)",
    )
    parser.add_argument(
        "--exclusive",
        action="store_true",
        help="open a WASAPI output in exclusive mode (Windows)",
    )
    parser.add_argument(
        "--period",
        type=int,
        metavar="FRAMES",
        help="the engine's block, frames (16 to 8192): on JACK a divisor of the server's "
        "period (e.g. 64 with 'jackd -p 64'), elsewhere each callback's frames (default: the "
        "sound card's period, else the device profile's block_frames)",
    )
    parser.add_argument(
        "--db",
        help="library of patterns, clips and wearer profiles, SQLite file (default: one per "
        "user, $XDG_DATA_HOME or ~/.local/share, then phantomtouch/patterns.db)",
    )
    parser.add_argument("--token", help="bearer token every request must carry")
    parser.add_argument(
        "--wearer",
        help="wearer profile from the library (PUT /wearers/NAME) the output stage applies",
    )
    parser.add_argument(
        "--wearer-band",
        choices=("sine_100hz", "noise_40_500hz"),
        help="band of the wearer profile to apply (default sine_100hz)",
    )
    parser.add_argument(
        "--bhaptics",
        metavar="HOST:PORT",
        help="also stand in for the bHaptics Player: its WebSocket protocol on this loopback "
        "address (the Player's is 127.0.0.1:15881)",
    )
    parser.add_argument(
        "--bhaptics-sdk2",
        metavar="HOST:PORT",
        help="where to serve bHaptics SDK2 (wss, v3) (default: --bhaptics's host, port 15882)",
    )
    parser.add_argument(
        "--bhaptics-map", help="bHaptics arm map file (TOML), with --bhaptics (docs/bhaptics.md)"
    )
    fleet_cli.add_serve_options(parser)


def _cmd_stop(args: argparse.Namespace) -> int:
    """``phantomtouch stop``: everything off through the service's own stop channel."""
    import os
    from pathlib import Path

    from phantomtouch.service.stop_channel import StopChannelError, send_stop, stop_file

    if not 1 <= args.port <= 65535:
        raise ParameterError(f"--port={args.port}: must be a port from 1 to 65535")
    folder = args.dir or os.environ.get("PHANTOMTOUCH_STOP_CHANNEL_DIR")
    path = stop_file(args.port, Path(folder) if folder else None)
    started_s = time.monotonic()
    try:
        answer = send_stop(path)
    except StopChannelError as exc:
        print(f"phantomtouch stop: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    took_ms = (time.monotonic() - started_s) * 1e3
    print(
        f"phantomtouch stop: everything off at server time {answer['server_time_s']:.3f} s "
        f"(answered in {took_ms:.1f} ms; frame {answer['frames']})"
    )
    return 0


def add_serve_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``serve``, ``osc``, ``stop`` and the fleet's ``gateway``."""
    serve = sub.add_parser("serve", help="run the touch service (REST and WebSocket)")
    _serve_arguments(serve)
    serve.add_argument("--osc", help="also receive OSC on this UDP HOST:PORT (loopback)")
    serve.add_argument("--osc-map", help="OSC map file (TOML), with --osc")
    serve.set_defaults(func=_cmd_serve)
    add_osc_command(sub, _serve_arguments, _cmd_serve)
    stop = sub.add_parser(
        "stop",
        help="turn everything off on the service of this machine at --port, through its own "
        "channel (works when its connections are exhausted)",
    )
    stop.add_argument("--port", type=int, default=8000, help="the service's HTTP port (8000)")
    stop.add_argument(
        "--dir", help="folder of its stop file (default: as the service's stop_channel_dir)"
    )
    stop.set_defaults(func=_cmd_stop)
    fleet_cli.register(sub)
