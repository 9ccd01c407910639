"""``phantomtouch osc``: the touch service with OSC input on.

``phantomtouch osc [--listen 127.0.0.1:9001] [--map FILE] [serve's options]`` is
``phantomtouch serve --osc 127.0.0.1:9001 [--osc-map FILE]``: the REST and WebSocket API
on its usual port, and an OSC listener on UDP feeding the same engine.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

DEFAULT_LISTEN = "127.0.0.1:9001"
"""Where VRChat sends OSC by default."""


def add_osc_command(
    sub: argparse._SubParsersAction,
    add_serve_arguments: Callable[[argparse.ArgumentParser], None],
    serve: Callable[[argparse.Namespace], int],
) -> None:
    """Register ``phantomtouch osc``: serve's options, ``--listen`` and ``--map``."""
    osc = sub.add_parser(
        "osc", help="run the touch service with OSC input (VRChat contact receivers, TouchOSC)"
    )
    add_serve_arguments(osc)
    osc.add_argument(
        "--listen",
        dest="osc",
        default=DEFAULT_LISTEN,
        help="UDP address to receive OSC on, loopback only (default %(default)s)",
    )
    osc.add_argument(
        "--map",
        dest="osc_map",
        help="OSC map file (TOML): avatar receivers on the forearm; default one per actuator; "
        "'bhaptics': a bHapticsOSC avatar's arm parameters",
    )
    osc.set_defaults(func=serve)
