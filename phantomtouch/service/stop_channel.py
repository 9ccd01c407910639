"""The emergency stop's own channel: one UDP socket on loopback, opened at start.

``POST /stop`` needs a connection, and a connection needs a file descriptor and a turn
of the event loop; a crowd of connections can take both. ``phantomtouch stop`` goes
another way, that needs neither: at start the service opens one UDP socket on
127.0.0.1 (an unused port) and a thread of its own that waits on it, and writes where
it listens, with a random secret, to :func:`stop_file` (readable by its user only;
removed at exit). A datagram ``stop SECRET`` turns everything off at once
(``Service.stop_everything``, from that thread) and is answered with a JSON datagram:
``{"stopped": true, "server_time_s", "frames"}`` (the server clock and the engine's
sample frame when the stop was applied). A datagram that does not carry the secret is
dropped unanswered and counted. Receiving a datagram opens nothing, so no number of
connections can starve it; the thread never waits on the event loop.
"""

from __future__ import annotations

import contextlib
import hmac
import json
import logging
import os
import secrets
import socket
import sys
import threading
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.server")

HOST = "127.0.0.1"
PREFIX = b"stop "
_POLL_S = 0.5
"""How often the thread looks whether the channel is closing."""


def runtime_dir() -> Path:
    """Where a running service keeps its stop file: ``$XDG_RUNTIME_DIR/phantomtouch``;
    without it ``%LOCALAPPDATA%\\phantomtouch\\run`` (Windows) or ``~/.phantomtouch/run``."""
    if os.environ.get("XDG_RUNTIME_DIR"):
        return Path(os.environ["XDG_RUNTIME_DIR"]) / "phantomtouch"
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "phantomtouch" / "run"
    return Path.home() / ".phantomtouch" / "run"


def stop_file(http_port: int, folder: Path | None = None) -> Path:
    """The stop file of the service listening on ``http_port`` (in :func:`runtime_dir`)."""
    return (folder or runtime_dir()) / f"stop-{http_port}.json"


class StopChannel:
    """The channel's socket, its thread and its file.

    Parameters
    ----------
    stop : callable
        Turns everything off and returns what the answer says (``server_time_s``,
        ``frames``); called on the channel's thread.
    path : Path
        The stop file to write (:func:`stop_file`).
    """

    def __init__(self, stop: Callable[[], dict[str, Any]], path: Path) -> None:
        self._stop = stop
        self.path = path
        self._secret = secrets.token_hex(16).encode()
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.bind((HOST, 0))
        self._socket.settimeout(_POLL_S)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stop-channel", daemon=True)
        self.refused = 0
        """Datagrams without the secret, dropped."""
        self.stops = 0

    @property
    def port(self) -> int:
        return int(self._socket.getsockname()[1])

    def start(self) -> None:
        """Write the stop file (owner only) and start the thread (caller's thread)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        record = {"host": HOST, "port": self.port, "secret": self._secret.decode()}
        staged = self.path.with_suffix(".tmp")
        staged.unlink(missing_ok=True)
        descriptor = os.open(staged, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(descriptor, "w") as out:
            json.dump(record, out)
        os.replace(staged, self.path)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread, close the socket, remove the stop file (caller's thread)."""
        self._closing.set()
        if self._thread.is_alive():
            self._thread.join(2 * _POLL_S)
        self._socket.close()
        with contextlib.suppress(OSError):
            if json.loads(self.path.read_text()).get("port") == self.port:
                self.path.unlink()

    def _run(self) -> None:
        while not self._closing.is_set():
            try:
                data, sender = self._socket.recvfrom(256)
            except TimeoutError:
                continue
            except OSError:
                if self._closing.is_set():
                    return
                continue
            if not (
                data.startswith(PREFIX)
                and hmac.compare_digest(data[len(PREFIX) :].strip(), self._secret)
            ):
                self.refused += 1
                continue
            answer = {"stopped": True, **self._stop()}
            self.stops += 1
            with contextlib.suppress(OSError):
                self._socket.sendto(json.dumps(answer).encode(), sender)


class StopChannelError(Exception):
    """No service answered the stop (the message says why)."""


def send_stop(path: Path, *, timeout_s: float = 1.0, attempts: int = 3) -> dict[str, Any]:
    """Ask the service whose stop file is ``path`` to stop everything; its answer.

    Each attempt waits ``timeout_s`` (s, > 0) for the answer (a datagram may be lost).

    Raises
    ------
    StopChannelError
        No stop file (no service on that port, or another user's), or no answer.
    """
    try:
        record = json.loads(path.read_text())
        address = (str(record["host"]), int(record["port"]))
        secret = str(record["secret"]).encode()
    except FileNotFoundError:
        raise StopChannelError(f"no running service wrote {path}") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise StopChannelError(f"{path} is not a stop file ({exc})") from exc
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(timeout_s)
        sock.connect(address)
        for _ in range(attempts):
            try:
                sock.send(PREFIX + secret)
                answer: dict[str, Any] = json.loads(sock.recv(1024))
                return answer
            except TimeoutError:
                continue
            except OSError as exc:  # nothing listens there: the service is gone
                raise StopChannelError(
                    f"no service at udp://{address[0]}:{address[1]} ({exc})"
                ) from exc
    raise StopChannelError(f"no answer from udp://{address[0]}:{address[1]} after {attempts} tries")


@asynccontextmanager
async def attach(service: Service, *, announce: str = "") -> AsyncIterator[None]:
    """What the server's lifespan enters first: the stop channel of ``service``, open
    while the service runs (an attachment, :data:`~phantomtouch.service.running.Attachment`);
    its start-up log line ends with ``announce`` (the connection budget)."""
    settings = service.settings

    def stop() -> dict[str, Any]:
        service.stop_everything()
        return {
            "server_time_s": service.engine.server_time_s(),
            "frames": service.engine.now_frames,
        }

    channel = StopChannel(stop, stop_file(settings.port, settings.stop_channel_dir))
    channel.start()
    logger.info(
        "phantomtouch: emergency stop on udp://%s:%d (phantomtouch stop)%s",
        HOST,
        channel.port,
        f"; {announce}" if announce else "",
    )
    try:
        yield
    finally:
        channel.close()
