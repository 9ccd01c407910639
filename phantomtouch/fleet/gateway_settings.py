"""Settings of a gateway (``PHANTOMTOUCH_GATEWAY_`` environment variables)."""

from __future__ import annotations

from typing import Self

from pydantic import Field, SecretStr, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from phantomtouch.fleet.auth import Grants, GrantSpec
from phantomtouch.service.settings import is_loopback


class GatewaySettings(BaseSettings):
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
    max_body_bytes: int = Field(default=1 << 20, ge=1024, le=64 << 20)
    max_ws_message_bytes: int = Field(default=64 << 10, ge=256, le=16 << 20)
    ws_messages_per_s: float = Field(default=1000.0, gt=0.0, le=1_000_000.0)
    watchdog_s: float = Field(default=2.0, ge=0.05, le=30.0)

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
