"""Fleet settings: the NATS servers, this node's armband id and site, heartbeat and TTL.

Credentials come from the environment only (``PHANTOMTOUCH_FLEET_USER`` and
``PHANTOMTOUCH_FLEET_PASSWORD``, ``PHANTOMTOUCH_FLEET_TOKEN`` or a credentials file
``PHANTOMTOUCH_FLEET_CREDS``); they are secrets, never printed or logged, and a server
URL that carries them is refused.
"""

from __future__ import annotations

from pathlib import Path
from typing import Self
from urllib.parse import urlsplit

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from phantomtouch.fleet.subjects import NAME_REGEX


class FleetSettings(BaseSettings):
    """How a node or a gateway joins the fleet; each field has a sane default."""

    model_config = SettingsConfigDict(env_prefix="PHANTOMTOUCH_FLEET_", extra="forbid")

    servers: list[str] = Field(
        default_factory=lambda: ["nats://127.0.0.1:4222"],
        min_length=1,
        description="NATS server URLs of the cluster (any one is enough to join).",
    )
    armband: str | None = Field(
        default=None, pattern=NAME_REGEX, description="This node's armband id."
    )
    site: str = Field(default="default", pattern=NAME_REGEX, description="This node's site.")
    heartbeat_s: float = Field(default=1.0, ge=0.05, le=30.0)
    ttl_s: float = Field(
        default=5.0,
        ge=0.5,
        le=300.0,
        description="A node missing heartbeats this long leaves the registry (the bucket's TTL).",
    )
    request_timeout_s: float = Field(default=2.0, gt=0.0, le=60.0)
    start_deadline_s: float = Field(
        default=20.0,
        gt=0.0,
        le=600.0,
        description="How long a node or gateway keeps trying to open and write the registry "
        "at start before it gives up (exit 1).",
    )
    sync_lead_s: float = Field(
        default=0.15,
        ge=0.0,
        le=10.0,
        description="How far ahead a touch to several armbands starts when no time is given.",
    )
    max_in_flight: int = Field(
        default=256, ge=1, le=65536, description="Touch requests a node handles at once."
    )
    user: str | None = None
    password: SecretStr | None = None
    token: SecretStr | None = None
    creds: Path | None = Field(default=None, description="NATS credentials file (.creds).")

    @property
    def beat_timeout_s(self) -> float:
        """How long one heartbeat may wait for the registry's answer, s.

        At most ``request_timeout_s``, and short enough that a heartbeat lost with its
        server (its reply never comes, even after the node has reconnected elsewhere) and
        the next one after it still land within ``ttl_s``: ``(ttl_s - heartbeat_s) / 2``,
        but never below ``heartbeat_s``. The defaults (1 s, 5 s) give 2 s.
        """
        half_slack_s = (self.ttl_s - self.heartbeat_s) / 2
        return min(self.request_timeout_s, max(self.heartbeat_s, half_slack_s))

    @field_validator("servers", mode="before")
    @classmethod
    def _split(cls, value: object) -> object:
        if isinstance(value, str):
            return [part.strip() for part in value.split(",") if part.strip()]
        return value

    @field_validator("servers")
    @classmethod
    def _urls(cls, servers: list[str]) -> list[str]:
        for server in servers:
            parts = urlsplit(server)
            if parts.scheme not in ("nats", "tls") or not parts.hostname:
                raise ValueError(f"servers: {server!r} must be nats://HOST:PORT or tls://HOST:PORT")
            if parts.username or parts.password:
                raise ValueError(
                    "servers: a URL must not carry credentials (they would be logged); set "
                    "PHANTOMTOUCH_FLEET_USER and PHANTOMTOUCH_FLEET_PASSWORD, "
                    "PHANTOMTOUCH_FLEET_TOKEN or PHANTOMTOUCH_FLEET_CREDS instead"
                )
        return servers

    @model_validator(mode="after")
    def _timing(self) -> Self:
        if self.ttl_s < 2 * self.heartbeat_s:
            raise ValueError(
                f"ttl_s={self.ttl_s!r} must be at least twice heartbeat_s={self.heartbeat_s!r}: "
                "one late heartbeat must not drop a live armband"
            )
        if (self.user is None) != (self.password is None):
            raise ValueError("user and password: give both (PHANTOMTOUCH_FLEET_USER/_PASSWORD)")
        return self
