"""Service settings: pydantic-settings with the ``PHANTOMTOUCH_`` environment prefix.

Every value is checked at start-up; nonsense (a port of 0, a watchdog of a minute, a
public bind address without a token) is refused before the engine or the socket opens.
"""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path
from typing import Annotated, Literal, Self

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from phantomtouch.schema import limits
from phantomtouch.schema.wearer import WEARER_NAME_REGEX, Band

CAPTURE_PREFIX = "capture:"
"""An ``output_device`` that records what plays to a WAV (``capture:FILE.wav``)."""

_LOOPBACK_NAMES = {"localhost", "ip6-localhost", "ip6-loopback"}
_HOST_NAME = re.compile(r"\*|\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_-]+(\.[A-Za-z0-9_-]+)*\.?")


def default_db_path() -> Path:
    """``$XDG_DATA_HOME/phantomtouch/patterns.db`` (``~/.local/share/...`` without it)."""
    import os

    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "phantomtouch" / "patterns.db"


def is_loopback(host: str) -> bool:
    """Whether ``host`` names only this machine (127.0.0.0/8, ::1, localhost)."""
    if host.lower() in _LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


VoiceCount = Annotated[int, Field(ge=1, le=4096)]
"""A number of pattern voices sounding at once (the engine mixes at most 4096)."""


class ClientLimits(BaseSettings):
    """What an HTTP server of the project allows each client (the touch service, a fleet
    gateway): request body and WebSocket message sizes, message rate and the watchdog."""

    model_config = SettingsConfigDict(use_attribute_docstrings=True)

    max_body_bytes: int = Field(default=1 << 20, ge=1024, le=64 << 20)
    """Largest request body in bytes (413 ``too_large`` beyond it)."""
    max_ws_message_bytes: int = Field(default=64 << 10, ge=256, le=16 << 20)
    """Largest WebSocket message in bytes (close 1009 beyond it)."""
    ws_messages_per_s: float = Field(default=1000.0, gt=0.0, le=1_000_000.0)
    """Messages per second one WebSocket connection may send (1 s of burst)."""
    watchdog_s: float = Field(default=2.0, ge=0.05, le=30.0)
    """Silence after which a connection's contacts are released, in seconds."""
    max_ws_connections: int = Field(default=64, ge=1, le=100_000)
    """WebSocket connections open at once in all, beyond which one from an address other than
    loopback is refused (close 1013); loopback ones are never refused."""
    max_ws_connections_per_address: int = Field(default=16, ge=1, le=100_000)
    """WebSocket connections open at once from one address other than loopback (close 1013 beyond
    it)."""


def _loopback_listen(listen: str | None, example_port: int, why: str) -> str | None:
    """``listen`` if it is ``HOST:PORT`` on a loopback host (None stays None; pure).

    Raises
    ------
    ValueError
        Not ``HOST:PORT`` with a port of 1-65535 (the message shows ``example_port``), or
        a host that is not loopback (the message says ``why`` the input listens on one).
    """
    if listen is None:
        return None
    host, _, port = listen.rpartition(":")
    if not host or not port.isdecimal() or not 1 <= int(port) <= 65535:
        raise ValueError(f"must be HOST:PORT, e.g. 127.0.0.1:{example_port}")
    if not is_loopback(host):
        raise ValueError(
            f"{why} on a loopback address only (127.0.0.1), where only programs of this "
            "machine reach it"
        )
    return listen


def _address(listen: str | None) -> tuple[str, int] | None:
    """A checked ``HOST:PORT`` listen setting as (host, port), brackets of an IPv6 host
    removed; None stays None (pure)."""
    if listen is None:
        return None
    host, _, port = listen.rpartition(":")
    return host.strip("[]"), int(port)


class Settings(ClientLimits):
    """Everything the service needs to start; each field has a sane default."""

    model_config = SettingsConfigDict(env_prefix="PHANTOMTOUCH_", extra="forbid")

    host: str = Field(default="127.0.0.1", min_length=1)
    """Address to bind."""
    port: int = Field(default=8000, ge=1, le=65535)
    contact_lane: bool = True
    """Run the contact lane (``docs/lane.md``); false: moves come over ``/ws`` only."""
    lane_port: int = Field(default=0, ge=0, le=65535)
    """UDP port of the contact lane on ``host``; 0: any free port (``welcome`` says which)."""
    device_profile: Path | None = None
    """Device profile file (TOML or JSON); None: the paper's armband."""
    output_device: str | None = None
    """Sound-card output (name, index or 'HOSTAPI:NAME', e.g. 'ASIO:Focusrite') for the engine;
    None: the first output with enough channels, else the null output. 'null' forces the null
    output; 'capture:FILE.wav' records what plays and writes it to that WAV at exit."""
    wasapi_exclusive: bool = False
    """Open the WASAPI output in exclusive mode (Windows; the output must be a WASAPI device, e.g.
    'WASAPI:Speakers')."""
    period_frames: int | None = Field(
        default=None, ge=limits.MIN_BLOCK_FRAMES, le=limits.MAX_BLOCK_FRAMES
    )
    """The engine's block, frames (``--period``): on JACK a divisor of the server's period
    (``jackd -p``), on other outputs the frames of each callback; None: the sound card's
    period (JACK's, or the buffer ASIO, Core Audio or WASAPI reports), else the device
    profile's ``block_frames``."""
    db_path: Path = Field(default_factory=default_db_path)
    """SQLite pattern store."""
    wearer: str | None = Field(default=None, pattern=WEARER_NAME_REGEX)
    """Wearer profile (stored in the library, PUT /wearers/{name}) whose offsets the output stage
    applies after the device's calibration; None: no profile."""
    wearer_band: Band = "sine_100hz"
    """Carrier band of the wearer profile the output stage applies."""
    token: str | None = Field(default=None, min_length=16)
    """Bearer token every request must carry (required off loopback)."""
    cors_origins: list[str] = Field(default_factory=list)
    """Web page origins besides the service's own allowed to call the API from a browser (CORS),
    e.g. 'http://localhost:5173'; '*' allows every page."""
    allowed_hosts: list[str] = Field(default_factory=list)
    """Host names the service answers to besides localhost, 127.0.0.1, [::1] and the bound address
    (any IP address when bound to 0.0.0.0 or ::); '*' allows any."""
    header_timeout_s: float = Field(default=10.0, ge=0.5, le=300.0)
    """Longest wait for a request's headers, in seconds (408 and closed beyond it)."""
    max_header_bytes: int = Field(default=64 << 10, ge=4096, le=1 << 20)
    """Largest request line and headers, in bytes (431 and closed beyond it)."""
    stop_channel_dir: Path | None = None
    """Folder of the stop file ``phantomtouch stop`` reads (None: ``$XDG_RUNTIME_DIR/phantomtouch``,
    else ``~/.phantomtouch/run``, on Windows ``%LOCALAPPDATA%\\phantomtouch\\run``)."""
    max_contacts_per_connection: int = Field(default=10, ge=1, le=256)
    """Contacts one WebSocket connection may hold down at once (two hands); the engine holds 128, so
    a dozen clients at their quota still leave room."""
    max_concurrent_renders: int = Field(default=2, ge=1, le=64)
    max_render_duration_s: float = Field(default=600.0, gt=0.0, le=7200.0)
    queue_capacity: int = Field(default=4096, ge=16, le=1 << 20)
    max_voices: VoiceCount = 64
    """Most pattern voices that may sound at once, whatever the render budget allows."""
    render_budget: float = Field(default=0.5, gt=0.0, le=1.0)
    """Share of an audio block's playing time that pattern voices may take to render; the engine
    measures what a voice costs and admits touches within it."""
    voice_policy: Literal["refuse", "steal-oldest", "steal-quietest"] = "steal-oldest"
    """A touch beyond the render budget: refused (503 busy), or the oldest or the quietest sounding
    touch fades out in 5 ms to make room for it."""
    max_voices_per_client: VoiceCount | None = None
    """Touches one client (a WebSocket connection, or an address over HTTP) may have scheduled or
    playing at once; None: three quarters of max_voices, so that one client never holds every
    voice."""
    max_voice_seconds_per_client: float = Field(default=14_400.0, gt=0.0, le=1_000_000.0)
    """Seconds of touch still to play that one client may hold, summed over its touches: long
    touches count by the time they hold (default: two of the longest, 2 h each)."""
    max_detached_voices_per_client: int = Field(default=4, ge=1, le=1000)
    """Detached touches (a WebSocket ``play`` with ``detached: true``: it plays on after the
    connection closes) one address may have scheduled or playing at once."""
    max_detached_seconds_per_client: float = Field(default=600.0, gt=0.0, le=1_000_000.0)
    """Seconds of detached touch still to play that one address may hold, summed."""
    engine_process: bool = True
    """Run the engine in a process of its own (the default), so that request handling never holds
    the interpreter lock its audio callback needs; False: a thread."""
    engine_log_path: Path | None = None
    """Where the engine logs what it played (None: no log)."""
    osc_listen: str | None = None
    """Listen for OSC over UDP at HOST:PORT, a loopback address (VRChat sends to 127.0.0.1:9001);
    None: no OSC input."""
    osc_map: Path | None = None
    """OSC map file (TOML): avatar receivers on the forearm; None: one per actuator."""
    osc_messages_per_s: float = Field(default=20_000.0, gt=0.0, le=1_000_000.0)
    """OSC messages admitted per second."""
    bhaptics_listen: str | None = None
    """Stand in for the bHaptics Player: accept its SDK1 WebSocket protocol at HOST:PORT, a
    loopback address (games connect to 127.0.0.1:15881); None: no bHaptics input."""
    bhaptics_sdk2_listen: str | None = None
    """Where to serve bHaptics SDK2 (v3, TLS), a loopback HOST:PORT; None: the host of
    ``bhaptics_listen`` and port 15882 (the Player's) when that is set."""
    bhaptics_map: Path | None = None
    """bHaptics arm map file (TOML): which arm positions play on the band and where; None: both
    arms, along the band's actuator span."""

    @property
    def voices_per_client(self) -> int:
        """``max_voices_per_client``, or three quarters of ``max_voices`` (at least 1)."""
        if self.max_voices_per_client is not None:
            return self.max_voices_per_client
        return max(1, (3 * self.max_voices) // 4)

    @field_validator("cors_origins")
    @classmethod
    def _origins(cls, origins: list[str]) -> list[str]:
        for origin in origins:
            if origin != "*" and not origin.startswith(("http://", "https://")):
                raise ValueError(f"cors_origins: {origin!r} must be '*' or start with http(s)://")
        return origins

    @field_validator("allowed_hosts")
    @classmethod
    def _hosts(cls, hosts: list[str]) -> list[str]:
        for host in hosts:
            if not _HOST_NAME.fullmatch(host):
                raise ValueError(
                    f"allowed_hosts: {host!r} must be a host name or address without scheme "
                    "or port, e.g. 'armband.local', '192.168.1.20' or '[fe80::1]'"
                )
        return [host.lower().rstrip(".") for host in hosts]

    @field_validator("osc_listen")
    @classmethod
    def _osc_listen(cls, listen: str | None) -> str | None:
        return _loopback_listen(listen, 9001, "OSC carries no token, so it listens")

    @field_validator("bhaptics_listen", "bhaptics_sdk2_listen")
    @classmethod
    def _bhaptics_listen(cls, listen: str | None) -> str | None:
        return _loopback_listen(
            listen, 15881, "bHaptics clients carry no token, so the stand-in listens"
        )

    @property
    def bhaptics_address(self) -> tuple[str, int] | None:
        """``bhaptics_listen`` as (host, port) (:func:`_address`)."""
        return _address(self.bhaptics_listen)

    @property
    def bhaptics_sdk2_address(self) -> tuple[str, int] | None:
        """Where SDK2 is served: ``bhaptics_sdk2_listen``, else port 15882 on the host of
        ``bhaptics_listen``; None when neither is set."""
        if self.bhaptics_sdk2_listen is not None:
            return _address(self.bhaptics_sdk2_listen)
        if self.bhaptics_address is None:
            return None
        return self.bhaptics_address[0], 15882

    @property
    def osc_address(self) -> tuple[str, int] | None:
        """``osc_listen`` as (host, port) (:func:`_address`)."""
        return _address(self.osc_listen)

    @field_validator("output_device")
    @classmethod
    def _output(cls, output: str | None) -> str | None:
        output = output.strip() or None if output is not None else None
        if output is not None and output.startswith(CAPTURE_PREFIX):
            path = Path(output.removeprefix(CAPTURE_PREFIX))
            if path.suffix.lower() != ".wav" or not path.parent.is_dir():
                raise ValueError(
                    f"output_device={output!r}: a capture output is 'capture:FILE.wav' in a "
                    "folder that exists"
                )
        return output

    @property
    def capture_path(self) -> Path | None:
        """The WAV a ``capture:`` output writes, else None."""
        output = self.output_device
        if output is None or not output.startswith(CAPTURE_PREFIX):
            return None
        return Path(output.removeprefix(CAPTURE_PREFIX))

    @model_validator(mode="after")
    def _public_bind_needs_token(self) -> Self:
        if not is_loopback(self.host) and self.token is None:
            raise ValueError(
                f"host={self.host!r} is not a loopback address: binding to it requires a "
                "token (PHANTOMTOUCH_TOKEN or --token, at least 16 characters)"
            )
        return self
