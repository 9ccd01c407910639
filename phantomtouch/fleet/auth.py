"""Who may address which armband through a gateway: scope tokens.

``PHANTOMTOUCH_GATEWAY_TOKENS`` holds a JSON object from token to grant::

    {"s3cret-token-of-alice": {"player": "alice", "armbands": ["alice-left", "alice-right"]},
     "operator-token-0123": {"player": "operator", "armbands": "*"}}

A player's token touches and stops only the armbands of its grant: ``POST /stop`` of
scope ``all`` or ``site`` with it stops only those of its armbands in that scope, and
``GET /armbands`` lists only them. ``--token`` (``PHANTOMTOUCH_GATEWAY_TOKEN``) is a token
of every armband. Without any token the gateway is open and listens on loopback only.
Tokens are compared in constant time and never logged.
"""

from __future__ import annotations

import hmac
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from phantomtouch.fleet.errors import ForbiddenArmbandError
from phantomtouch.fleet.subjects import NAME_REGEX


class GrantSpec(BaseModel):
    """One token's grant as written in ``PHANTOMTOUCH_GATEWAY_TOKENS``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    player: str = Field(min_length=1, max_length=64)
    armbands: Literal["*"] | list[str] = Field(description="Armband ids, or '*' for all.")


@dataclass(frozen=True)
class Grant:
    """What one request may address."""

    player: str
    armbands: frozenset[str] | None
    """None: every armband."""

    def allows(self, armband: str) -> bool:
        return self.armbands is None or armband in self.armbands

    def check(self, armband: str) -> None:
        """Refuse (403 ``forbidden``) an armband outside the grant."""
        if not self.allows(armband):
            raise ForbiddenArmbandError(armband, self.player)

    def within(self, armbands: Iterable[str]) -> list[str]:
        return [armband for armband in armbands if self.allows(armband)]


EVERYTHING = Grant(player="any", armbands=None)


class Grants:
    """Tokens and their grants; :meth:`grant` finds a request's."""

    def __init__(self, tokens: dict[str, GrantSpec], *, admin_token: str | None) -> None:
        import re

        pattern = re.compile(NAME_REGEX)
        self._grants: list[tuple[bytes, Grant]] = []
        for token, spec in tokens.items():
            if len(token) < 16:
                raise ValueError(
                    f"tokens: the token of player {spec.player!r} is under 16 characters"
                )
            armbands = None if spec.armbands == "*" else frozenset(spec.armbands)
            for armband in armbands or ():
                if not pattern.fullmatch(armband):
                    raise ValueError(
                        f"tokens: armband {armband!r} of player {spec.player!r} is not an id"
                    )
            self._grants.append((token.encode(), Grant(spec.player, armbands)))
        if admin_token is not None:
            self._grants.append((admin_token.encode(), EVERYTHING))

    @property
    def open(self) -> bool:
        """No token at all: every request may address every armband."""
        return not self._grants

    def grant(self, given: str | None) -> Grant | None:
        """The grant of token ``given``; None when it matches none (or none was given)."""
        if self.open:
            return EVERYTHING
        if given is None:
            return None
        found = None
        for token, grant in self._grants:
            if hmac.compare_digest(given.encode(), token):
                found = grant
        return found
