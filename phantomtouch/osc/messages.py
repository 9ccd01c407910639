"""The OSC addresses the bridge knows and the arguments each takes, checked.

Generic addresses (TouchOSC, Max, Pure Data, SuperCollider):

``/phantomtouch/touch  s``
    play a preset (``exp2/curved``) or a stored pattern by its name;
``/phantomtouch/contact/{id}  f f f``
    x_cm, y_cm, intensity (0-1) of live contact ``id``: it touches down on its first
    message, moves on the next ones, and lifts off at intensity 0;
``/phantomtouch/stop``
    every pattern and contact off, as ``POST /stop``.

Receivers of the map file take one float (or int) proximity in [0, 1]; an OSC ``T``/``F``
(a receiver driving a bool parameter) is 1 or 0. A message that breaks these rules raises
:class:`BadMessage`, whose ``reason`` is one of :data:`~phantomtouch.osc.counters.REASONS`.
"""

from __future__ import annotations

import math
import re
from typing import Any

from phantomtouch.errors import ParameterError
from phantomtouch.schema import limits

TOUCH = "/phantomtouch/touch"
STOP = "/phantomtouch/stop"
CONTACT_PREFIX = "/phantomtouch/contact/"
_CONTACT_ID = re.compile(r"[A-Za-z0-9_.-]{1,48}")
_MAX_NAME = 128


class BadMessage(ParameterError):
    """An OSC message the bridge drops; ``reason`` says which rule it broke."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def _number(address: str, name: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadMessage(
            "bad_arguments", f"{address}: {name}={value!r} must be a float (OSC type f or i)"
        )
    number = float(value)
    if not math.isfinite(number):
        raise BadMessage("not_finite", f"{address}: {name}={value!r} must be finite")
    if not low <= number <= high:
        raise BadMessage(
            "out_of_range", f"{address}: {name}={value!r} must be >= {low:g} and <= {high:g}"
        )
    return number


def _count(address: str, args: tuple[Any, ...], expected: int, what: str) -> None:
    if len(args) != expected:
        raise BadMessage(
            "bad_arguments", f"{address}: expected {expected} argument(s) ({what}), got {len(args)}"
        )


def proximity(address: str, args: tuple[Any, ...]) -> float:
    """A receiver's proximity, 0-1."""
    _count(address, args, 1, "proximity 0-1")
    value = args[0]
    if isinstance(value, bool):
        return 1.0 if value else 0.0
    return _number(address, "proximity", value, 0.0, 1.0)


def contact_id(address: str) -> str:
    """The ``{id}`` of ``/phantomtouch/contact/{id}``."""
    name = address.removeprefix(CONTACT_PREFIX)
    if not _CONTACT_ID.fullmatch(name):
        raise BadMessage(
            "bad_arguments",
            f"{address}: the contact id {name!r} must be 1-48 letters, digits, '_', '.' or '-'",
        )
    return name


def contact(address: str, args: tuple[Any, ...]) -> tuple[float, float, float]:
    """``(x_cm, y_cm, intensity)`` of a contact message."""
    _count(address, args, 3, "x_cm, y_cm, intensity")
    bound = limits.MAX_COORD_CM
    return (
        _number(address, "x_cm", args[0], -bound, bound),
        _number(address, "y_cm", args[1], -bound, bound),
        _number(address, "intensity", args[2], 0.0, 1.0),
    )


def touch_name(address: str, args: tuple[Any, ...]) -> str:
    """The preset or stored pattern name of ``/phantomtouch/touch``."""
    _count(address, args, 1, "a preset or stored pattern name")
    name = args[0]
    if not isinstance(name, str) or not 0 < len(name) <= _MAX_NAME:
        raise BadMessage(
            "bad_arguments",
            f"{address}: name={name!r} must be a string (OSC type s) of 1-{_MAX_NAME} characters",
        )
    return name


def no_arguments(address: str, args: tuple[Any, ...]) -> None:
    _count(address, args, 0, "none")
