"""Settings of a gateway (``PHANTOMTOUCH_GATEWAY_`` environment variables)."""

from __future__ import annotations

from typing import Self

from pydantic import Field, SecretStr, model_validator
from pydantic_settings import SettingsConfigDict

from phantomtouch.fleet.auth import Grants, GrantSpec
from phantomtouch.service.settings import ClientLimits, is_loopback


class GatewaySettings(ClientLimits):
    """Where a gateway listens and what it lets through."""

    model_config = SettingsConfigDict(env_prefix="PHANTOMTOUCH_GATEWAY_", extra="forbid")

    host: str = Field(default="127.0.0.1", min_length=1)
    port: int = Field(default=8100, ge=1, le=65535)
    token: SecretStr | None = Field(
        default=None, min_length=16, description="A token of every armband."
    )
    tokens: dict[str, GrantSpec] = Field(
        default_factory=dict, description="Player tokens and their armbands (JSON)."
    )
    allowed_hosts: list[str] = Field(default_factory=list)

    def grants(self) -> Grants:
        admin = self.token.get_secret_value() if self.token is not None else None
        return Grants(self.tokens, admin_token=admin)

    @model_validator(mode="after")
    def _checked(self) -> Self:
        self.grants()
        if not is_loopback(self.host) and self.token is None and not self.tokens:
            raise ValueError(
                f"host={self.host!r} is not a loopback address: a gateway there needs tokens "
                "(PHANTOMTOUCH_GATEWAY_TOKEN or PHANTOMTOUCH_GATEWAY_TOKENS)"
            )
        return self
