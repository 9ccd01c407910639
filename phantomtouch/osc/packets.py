"""One UDP datagram to OSC messages, or a named reason to drop it.

A datagram is an OSC message (it starts with ``/``) or a bundle (``#bundle\\0``, a time
tag, then elements, each a 4-byte big-endian size and that many bytes of message or
bundle). Bundles are taken apart with an explicit stack, never by recursion, to at most
:data:`MAX_BUNDLE_DEPTH` levels; every element's declared size must fit in what follows.
Each message's address and type tags are checked here before python-osc reads its
arguments: addresses and strings must be UTF-8 and every type tag one that python-osc
reads (it would log a line per unknown tag and skip it). Anything else python-osc
raises while reading a message counts as ``malformed``: no datagram can raise out of
:func:`messages_of`.
"""

from __future__ import annotations

import struct
from typing import Any

from pythonosc.osc_message import OscMessage

BUNDLE_PREFIX = b"#bundle\x00"
MAX_BUNDLE_DEPTH = 8
"""Bundles inside bundles a datagram may nest (the outermost is depth 1)."""
TYPE_TAGS = frozenset("ifsdbhrmtTFN[]")
"""The argument types python-osc reads."""
_TIME_TAG_BYTES = 8
_SIZE = struct.Struct(">i")


class BadDatagram(ValueError):
    """A datagram dropped as a whole; ``reason`` names the rule it broke.

    Reasons: ``malformed`` (not OSC, or cut short), ``too_deep`` (bundles nested beyond
    :data:`MAX_BUNDLE_DEPTH`), ``bad_bundle_size`` (an element's declared size exceeds
    what follows, or is negative), ``not_utf8`` (an address or string argument that is
    not UTF-8), ``bad_type_tag`` (type tags not starting with ``,`` or naming a type
    python-osc does not read).
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def messages_of(data: bytes) -> list[tuple[str, tuple[Any, ...]]]:
    """Every message of ``data`` as ``(address, arguments)``, in the datagram's order.

    Raises
    ------
    BadDatagram
        Anything in the datagram breaks a rule; none of its messages are returned.
    """
    found: list[tuple[str, tuple[Any, ...]]] = []
    stack: list[tuple[bytes, int]] = [(data, 1)]
    while stack:
        element, depth = stack.pop()
        if element.startswith(b"/"):
            found.append(_message(element))
        elif element.startswith(BUNDLE_PREFIX):
            if depth > MAX_BUNDLE_DEPTH:
                raise BadDatagram(
                    "too_deep",
                    f"bundles nested deeper than {MAX_BUNDLE_DEPTH} (max_bundle_depth)",
                )
            stack.extend((part, depth + 1) for part in reversed(_elements(element)))
        else:
            raise BadDatagram(
                "malformed", f"an element of {len(element)} bytes is neither a message nor a bundle"
            )
    return found


def _elements(bundle: bytes) -> list[bytes]:
    index = len(BUNDLE_PREFIX) + _TIME_TAG_BYTES
    if len(bundle) < index:
        raise BadDatagram("malformed", f"a bundle of {len(bundle)} bytes has no time tag")
    parts = []
    while index < len(bundle):
        if index + _SIZE.size > len(bundle):
            raise BadDatagram("malformed", "a bundle element's size is cut short")
        (size,) = _SIZE.unpack_from(bundle, index)
        index += _SIZE.size
        left = len(bundle) - index
        if not 0 <= size <= left:
            raise BadDatagram(
                "bad_bundle_size",
                f"a bundle element declares size={size} bytes but {left} follow",
            )
        parts.append(bundle[index : index + size])
        index += size
    return parts


def _string_end(data: bytes, start: int, what: str) -> tuple[str, int]:
    end = data.find(b"\x00", start)
    if end < 0:
        raise BadDatagram("malformed", f"the {what} has no terminating null")
    try:
        text = data[start:end].decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BadDatagram("not_utf8", f"the {what} is not UTF-8 ({exc.reason})") from None
    return text, (end // 4 + 1) * 4


def _message(data: bytes) -> tuple[str, tuple[Any, ...]]:
    address, index = _string_end(data, 0, "address")
    shown = address[:64]
    if index < len(data):
        tags, _ = _string_end(data, index, f"type tags of {shown!r}")
        unknown = sorted(set(tags[1:]) - TYPE_TAGS)
        if not tags.startswith(",") or unknown:
            raise BadDatagram(
                "bad_type_tag",
                f"{shown}: type tags {tags[:32]!r} must start with ',' and use only "
                f"{''.join(sorted(TYPE_TAGS))}",
            )
    try:
        message = OscMessage(data)
    except UnicodeDecodeError as exc:
        raise BadDatagram("not_utf8", f"{shown}: a string argument is not UTF-8") from exc
    except Exception as exc:  # python-osc's ParseError, or any slip in its reading
        raise BadDatagram("malformed", f"{shown}: {exc}") from exc
    return address, tuple(message.params)
