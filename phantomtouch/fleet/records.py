"""What travels on the fleet's subjects and sits in its registry (docs/fleet.md).

Every model refuses unknown fields and is validated strictly from the JSON bytes, as
the REST bodies are; the touch inside a :class:`FleetTouch` is validated by the same
parser as ``POST /touch``.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Self

from pydantic import BaseModel, ConfigDict, Field

from phantomtouch.errors import ParameterError
from phantomtouch.fleet.subjects import NAME_REGEX

ArmbandId = Annotated[str, Field(pattern=NAME_REGEX, description="An armband id.")]
SiteName = Annotated[str, Field(pattern=NAME_REGEX, description="A site name.")]
Owner = Annotated[str, Field(min_length=1, max_length=128)]
UnixTime = Annotated[float, Field(ge=0.0, le=1e11, allow_inf_nan=False)]


class _Record(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Load(_Record):
    active_voices: int
    voice_capacity: int
    active_contacts: int
    underruns: int


class ArmbandRecord(_Record):
    """One armband's registry entry, rewritten every heartbeat."""

    armband: ArmbandId
    site: SiteName
    device: dict[str, Any] = Field(description="channels, sample_rate_hz, block_frames, actuators")
    output: str = Field(description="Where the engine plays (sound card or null output).")
    status: Literal["ok", "degraded"]
    load: Load
    server_time_s: float = Field(description="The node's engine clock at the heartbeat.")
    unix_time_s: float = Field(description="The node's wall clock at the heartbeat.")
    clock_offset_s: float | None = Field(
        description=(
            "The node's wall clock minus the NATS server's time stamp of its previous "
            "heartbeat (positive: the node is ahead), within that publish's one-way latency; "
            "None before the first heartbeat was read back."
        )
    )
    heartbeat_s: float
    ttl_s: float
    version: str


class FleetTouch(_Record):
    """A touch request on ``phantomtouch.armband.ID.touch``."""

    touch: dict[str, Any] = Field(description="The body of POST /touch.")
    start_at_unix_s: UnixTime | None = Field(
        default=None, description="Start at this wall-clock time (hosts NTP-synced)."
    )
    client: Owner = Field(default="fleet", description="Whose quotas the touch counts against.")
    principal: str | None = Field(
        default=None,
        max_length=40,
        description="Who the client is (a gateway's: 'fleet:HOST' or 'token:DIGEST'); "
        "believed on a closed cluster only.",
    )


class FleetAnswer(_Record):
    """The answer to a touch, a contact ``down`` or a stop: REST's status and body."""

    status: int
    body: dict[str, Any]


class StopRequest(_Record):
    """A stop: everything on the armbands in scope, or one job of the addressed armband."""

    job_id: Annotated[str, Field(min_length=1, max_length=64)] | None = None


class StopScope(_Record):
    """The body of the gateway's ``POST /stop``; no body at all means ``all``."""

    scope: Literal["all", "site", "armband"] = "all"
    site: SiteName | None = None
    armband: ArmbandId | None = None

    def check(self) -> Self:
        """Refuse (:class:`ParameterError`, naming the field) a target the scope lacks or
        does not take: ``site`` goes with ``site``, ``armband`` with ``armband``."""
        needed = {"all": None, "site": "site", "armband": "armband"}[self.scope]
        for name in ("site", "armband"):
            value = getattr(self, name)
            if value is not None and name != needed:
                raise ParameterError(f"{name}={value!r}: not allowed with scope={self.scope!r}")
            if value is None and name == needed:
                raise ParameterError(f"{name}=null: required with scope={self.scope!r}")
        return self


class ClockAnswer(_Record):
    armband: ArmbandId
    unix_time_s: float
    server_time_s: float
