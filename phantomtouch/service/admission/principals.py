"""Principals and owner ids: who a source really is, and the name its owner goes by.

A **principal** is who a source really is: for an input that checked a token, the token
(every input with that token is one principal); otherwise the input kind and the source's
host (every source port and connection of one host on one input is one principal). An
**owner** is one source of a principal (a WebSocket connection, an OSC source port, a
fleet owner id); its id is ``PRINCIPAL/SOURCE``
(:data:`~phantomtouch.engine.shares.PRINCIPAL_SEPARATOR`), which is how the engine's fair
shares see the principal (:func:`~phantomtouch.engine.shares.principal_of`). This module
is the one place both are made.
"""

from __future__ import annotations

import hashlib

from phantomtouch.engine.shares import PRINCIPAL_SEPARATOR
from phantomtouch.errors import ParameterError

MAX_PRINCIPAL_CHARS = 40
"""A principal longer than this (a long IPv6 host) is shortened to a digest of it."""
MAX_OWNER_CHARS = 64
"""The engine's limit of an owner id."""
DETACHED = "detached"
"""The source name of a principal's detached touches (they outlive the source)."""


def _digest(text: str, chars: int) -> str:
    return hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:chars]


def principal_for(kind: str, *, host: str | None, token: str | None = None) -> str:
    """The principal of a source of input ``kind`` (host, any thread; pure).

    Parameters
    ----------
    kind : str
        The input kind (``ws``, ``osc``, ...).
    host : str or None
        The source's host (its peer address); None: unknown (all unknown hosts of the
        kind are one principal).
    token : str or None
        The token the source proved it holds (None: it proved none). The token itself never
        appears in the principal, only a digest of it.

    Returns
    -------
    str
        ``token:DIGEST`` or ``KIND:HOST`` (``KIND:#DIGEST`` when that is longer than
        :data:`MAX_PRINCIPAL_CHARS`), without :data:`PRINCIPAL_SEPARATOR`.
    """
    if token is not None:
        return f"token:{_digest(token, 16)}"
    label = f"{kind}:{host or 'unknown'}"
    if len(label) > MAX_PRINCIPAL_CHARS or PRINCIPAL_SEPARATOR in label:
        label = f"{kind}:#{_digest(host or '', 16)}"
    return label


def check_principal(principal: str) -> str:
    """``principal`` if it is one :func:`principal_for` makes, else ParameterError."""
    if (
        not isinstance(principal, str)
        or not 0 < len(principal) <= MAX_PRINCIPAL_CHARS
        or PRINCIPAL_SEPARATOR in principal
    ):
        raise ParameterError(
            f"principal={principal!r} must be 1-{MAX_PRINCIPAL_CHARS} characters without "
            f"{PRINCIPAL_SEPARATOR!r} (principal_for makes one)"
        )
    return principal


def owner_id(principal: str, source: str) -> str:
    """The engine owner of ``source`` of ``principal``: ``PRINCIPAL/SOURCE``, at most
    :data:`MAX_OWNER_CHARS` characters (a longer source is named by a digest of it)."""
    room = MAX_OWNER_CHARS - len(principal) - len(PRINCIPAL_SEPARATOR)
    tag = source if 0 < len(source) <= room else "#" + _digest(source, min(16, room - 1))
    return f"{principal}{PRINCIPAL_SEPARATOR}{tag}"
