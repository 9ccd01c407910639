"""The OSC bridge: a UDP socket, its receive thread, and what each message does.

One thread receives datagrams, takes them apart (:mod:`~phantomtouch.osc.packets`, which
reads each message with python-osc) and handles each message at once, in arrival order:
receiver proximities become live contacts (:mod:`~phantomtouch.osc.receivers`),
``/phantomtouch/...`` messages touch, move, lift, play and stop
(:mod:`~phantomtouch.osc.messages`). It calls the engine's control side
(:class:`~phantomtouch.engine.EngineFront`), which never waits for the audio: a move
reaches the audio at the next block. Bundles are taken apart and their messages applied
on arrival; their time tags are ignored (python-osc's own dispatcher would sleep until a
future time tag, which lets one datagram stall the bridge, and drops unparsable
datagrams without counting them, hence the loop here).

Safety: every datagram and message is checked and a bad one dropped, counted
(:class:`~phantomtouch.osc.counters.OscCounters`) and logged in one line, at most one per
reason every :data:`LOG_INTERVAL_S`; a token bucket bounds the message rate. The bridge
keeps no contact state: its contacts are held by the engine's front, by sender (owner
``osc:HOST:PORT``, :mod:`~phantomtouch.osc.senders`, :mod:`phantomtouch.engine.owners`),
each with the map's ``watchdog_s`` as its deadline, which every accepted message of the
same sender pushes on (another sender's messages never do). A sender's silence for
``watchdog_s`` releases its contacts -- by the front's deadline thread, so also when this
thread is gone -- and closing the bridge releases them all. The generic contacts the bridge
holds (at most :data:`MAX_CONTACTS`) are shared fairly between senders
(:mod:`phantomtouch.engine.shares`). The receive thread is supervised: should it die
anyway, the bridge's contacts are released at once and a new thread started
(:meth:`OscBridge.health`). A contact that the engine let go of meanwhile (``POST /stop``,
an engine restart, its deadline) touches down again on its sender's next message.
"""

from __future__ import annotations

import collections
import logging
import socket
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from phantomtouch.engine.shares import yielding
from phantomtouch.engine.thread_priority import raise_thread_priority
from phantomtouch.errors import DeviceError, PhantomTouchError, ProtocolError, install_hint
from phantomtouch.osc import messages
from phantomtouch.osc.counters import OscCounters
from phantomtouch.osc.mapping import ReceiverMap
from phantomtouch.osc.receivers import Change, ReceiverLayout
from phantomtouch.osc.senders import OWNER_PREFIX, Sender, SenderTable
from phantomtouch.service.flood import FloodGuard, LimitedLog
from phantomtouch.service.running import InputHealth

try:
    from phantomtouch.osc.packets import BadDatagram, messages_of
except ImportError as exc:  # pragma: no cover - the osc extra is missing
    raise ImportError(f"OSC input needs python-osc, the osc extra: {install_hint('osc')}") from exc

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront

logger = logging.getLogger("phantomtouch.osc")

INPUT = "osc"
"""The input's name in ``/health`` (its owners: ``osc:HOST:PORT``, one per sender)."""
RATE_PER_S = 20_000.0
"""Default of the message rate limit of one sender: 8 receivers at 90 Hz are 720 messages/s."""
TOTAL_RATE_FACTOR = 2.0
"""Every sender together may send this many times one sender's rate: one flooding sender
takes at most half of what the bridge admits."""
MAX_CONTACTS = 10
"""Generic contacts (``/phantomtouch/contact/{id}``) the bridge holds at once, over every
sender (shared by :func:`~phantomtouch.engine.shares.yielding`)."""
CONTACT_PREFIX = "contact-"
"""Engine contact ids of generic contacts start with this (receivers' with ``receivers-``)."""
_POLL_S = 0.05
"""The receive timeout: how often the loop looks at the closing flag when nothing arrives."""
_MAX_DATAGRAM = 65_536
_RECEIVE_BUFFER_BYTES = 1 << 20
"""Room for bursts (every parameter of an avatar at once) while the thread is busy."""
_LATENCIES = 1 << 20
DEGRADED_AFTER_RESTART_S = 60.0
"""``/health`` names the input as degraded this long after its thread was restarted."""
MAX_RESTART_PAUSE_S = 1.0
"""The longest pause before a failed receive thread is started again."""
LOG_INTERVAL_S = 10.0
"""Drops of one reason log one line per this interval at most (a flood is counted)."""


class OscBridge:
    """Receives OSC on ``host:port`` and drives ``engine``.

    Parameters
    ----------
    engine : EngineFront
    receiver_map : ReceiverMap
        The receivers and how they become contacts.
    host, port : str, int
        Where to listen (UDP); port 0 picks a free one (see :attr:`address`).
    play : callable or None
        ``play(name, owner)`` plays a preset or stored pattern for the sender ``owner``
        (``osc:HOST:PORT``, its quota's client); it may raise
        :class:`~phantomtouch.errors.PhantomTouchError`. None: presets only, planned and
        scheduled here.
    stop : callable or None
        What ``/phantomtouch/stop`` does besides dropping the bridge's contacts; None:
        ``engine.stop_all()``.
    rate_per_s : float, > 0
        Messages per second admitted from each sender (one second of burst), and
        :data:`TOTAL_RATE_FACTOR` times that from every sender together; more are dropped
        (``flood``), a sender's own excess before it counts against the others.
    record_latency : bool
        Keep each datagram's receipt-to-engine time in :attr:`latencies_s` (benchmarks).
    """

    def __init__(
        self,
        engine: EngineFront,
        receiver_map: ReceiverMap,
        *,
        host: str = "127.0.0.1",
        port: int = 9001,
        play: Callable[[str, str], None] | None = None,
        stop: Callable[[], None] | None = None,
        rate_per_s: float = RATE_PER_S,
        record_latency: bool = False,
    ) -> None:
        self.engine = engine
        self.map = receiver_map
        self.counters = OscCounters()
        self.watchdog_releases = 0
        self.latencies_s: collections.deque[float] | None = (
            collections.deque(maxlen=_LATENCIES) if record_latency else None
        )
        self._play = play or self._play_preset
        self._stop = stop or engine.stop_all
        self._flood = FloodGuard(rate_per_s * TOTAL_RATE_FACTOR)
        self._index = {r.address: i for i, r in enumerate(receiver_map.receiver)}
        self._layout = ReceiverLayout(
            np.array([(r.x_cm, r.y_cm) for r in receiver_map.receiver]),
            receiver_map.cluster_gap_cm,
        )
        self._senders = SenderTable(
            len(receiver_map.receiver), receiver_map.smoothing_s, rate_per_s
        )
        self._let_go: collections.deque[tuple[str, str]] = collections.deque()
        self._unsubscribe = engine.subscribe_released(self._released)
        self._log = LimitedLog(logger, LOG_INTERVAL_S)
        self.restarts = 0
        self.last_failure: str | None = None
        self._restarted_s: float | None = None
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        self._socket = open_socket(host, port)
        self._socket.settimeout(_POLL_S)

    @property
    def address(self) -> tuple[str, int]:
        """The (host, port) the bridge listens on."""
        host, port = self._socket.getsockname()[:2]
        return str(host), int(port)

    @property
    def contacts(self) -> list[str]:
        """Engine contact ids the bridge holds down now, over every sender (as the engine's
        front says)."""
        held = self.engine.contact_owners(OWNER_PREFIX).values()
        return sorted(contact for contacts in held for contact in contacts)

    def _released(self, owner: str, contacts: tuple[str, ...], reason: str) -> None:
        """The front let go of contacts (any thread): of a sender of the bridge, count a
        watchdog release; the receive thread forgets their smoothing state."""
        if not owner.startswith(OWNER_PREFIX):
            return
        if reason == "watchdog":
            self.watchdog_releases += 1
        self._let_go.extend((owner, contact) for contact in contacts)

    def start(self) -> None:
        """Start the receive thread (in the caller's thread)."""
        self.engine.prepare_carrier(self.map.carrier)
        self._spawn()

    def health(self) -> InputHealth:
        """How the receive thread fares (any thread): ``running`` or ``restarting``, its
        restarts and the last failure; ``degraded`` while it is down or for
        :data:`DEGRADED_AFTER_RESTART_S` after a restart."""
        thread = self._thread
        alive = thread is not None and thread.is_alive()
        recent = (
            self._restarted_s is not None
            and time.monotonic() - self._restarted_s < DEGRADED_AFTER_RESTART_S
        )
        return InputHealth(
            state="running" if alive else "restarting",
            degraded=not alive or recent,
            restarts=self.restarts,
            last_failure=self.last_failure,
        )

    def _spawn(self) -> None:
        self._thread = threading.Thread(
            target=self._supervised, name="phantomtouch-osc", daemon=True
        )
        self._thread.start()

    def _supervised(self) -> None:
        """The receive thread: the loop, and what happens if it dies anyway."""
        try:
            self._run()
        except BaseException as exc:  # the input outlives its own failure
            if not self._closing.is_set():
                self._restart(exc)

    def _restart(self, exc: BaseException) -> None:
        """The loop died: release its contacts at once, then start a new thread (after
        a pause that grows with repeated failures, at most :data:`MAX_RESTART_PAUSE_S`)."""
        self.restarts += 1
        self.last_failure = f"{type(exc).__name__}: {exc}"[:200]
        self._restarted_s = time.monotonic()
        logger.error(
            "osc: the receive thread died (%s); its contacts are released and it restarts",
            self.last_failure,
        )
        try:
            self._release_all("input failed")
        except Exception as release_exc:  # the engine has its own watchdog
            logger.error("osc: releasing the bridge's contacts failed (%s)", release_exc)
        pause_s = min(MAX_RESTART_PAUSE_S, 0.05 * 2 ** min(self.restarts, 10))
        if not self._closing.wait(pause_s):
            self._spawn()

    def close(self) -> None:
        """Stop receiving and release every contact of the bridge."""
        self._closing.set()
        thread = self._thread
        while thread is not None:
            thread.join()
            thread, done = self._thread, thread
            if thread is done:
                break
        self._socket.close()
        self._release_all("closed")
        self._unsubscribe()

    def __enter__(self) -> OscBridge:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the receive loop ---------------------------------------------------------------

    def _run(self) -> None:
        raise_thread_priority("the OSC bridge")  # a move is not late behind busy processes
        receive = self._socket.recvfrom
        while not self._closing.is_set():
            try:
                data, peer = receive(_MAX_DATAGRAM)
            except TimeoutError:
                continue
            except OSError:
                if self._closing.is_set():
                    return
                raise
            received_s = time.perf_counter()
            while self._let_go:
                owner, contact = self._let_go.popleft()
                if (gone := self._senders.get(owner)) is not None:
                    gone.tracker.live.pop(contact, None)
            self._datagram(data, peer, time.monotonic())
            if self.latencies_s is not None:
                self.latencies_s.append(time.perf_counter() - received_s)

    def _datagram(self, data: bytes, peer: tuple[str, int], now_s: float) -> None:
        try:
            found = messages_of(data)
        except BadDatagram as exc:
            self._drop(exc.reason, f"a datagram of {len(data)} bytes: {exc}")
            return
        sender, dropped = self._senders.heard(peer)
        if dropped is not None:  # silent longest of MAX_SENDERS: its contacts go with it
            self.engine.release_owner(dropped.owner, "quota")
        for address, args in found:
            if not sender.flood.admit(now_s):
                self._drop(
                    "flood", f"{sender.owner} over its rate of {sender.flood.rate_per_s:g}/s"
                )
                continue
            if not self._flood.admit(now_s):
                self._drop("flood", f"every sender together over {self._flood.rate_per_s:g}/s")
                continue
            try:
                self._handle(sender, address, args, now_s)
            except messages.BadMessage as exc:
                self._drop(exc.reason, str(exc))
            except PhantomTouchError as exc:
                self._drop("refused", str(exc))
            except Exception as exc:  # the loop (and its watchdog) must outlive any message
                self._drop("failed", f"{address[:64]}: {type(exc).__name__}: {exc}")
            else:
                self.counters.count("accepted")
                self.engine.renew_owner(sender.owner)

    def _drop(self, reason: str, message: str) -> None:
        self.counters.count(reason)
        self._log.warning(reason, f"osc: dropped ({reason}): {message}")

    def _release_all(self, reason: str) -> None:
        """Forget the smoothing state and let the front release every contact of every
        sender, published with ``reason`` (the receive thread, or the one closing it)."""
        self._senders.forget_all()
        for owner in self.engine.contact_owners(OWNER_PREFIX):
            self.engine.release_owner(owner, reason)

    # -- messages -------------------------------------------------------------------------

    def _handle(self, sender: Sender, address: str, args: tuple[Any, ...], now_s: float) -> None:
        index = self._index.get(address)
        if index is not None:
            sender.proximity[index] = messages.proximity(address, args)
            self._receivers(sender, now_s)
        elif address.startswith(messages.CONTACT_PREFIX):
            self._contact(sender.owner, address, args)
        elif address == messages.TOUCH:
            self._play(messages.touch_name(address, args), sender.owner)
        elif address == messages.STOP:
            messages.no_arguments(address, args)
            self._senders.forget_all()
            self._stop()
        else:
            raise messages.BadMessage(
                "unknown_address",
                f"address={address!r} is neither a receiver of the map nor "
                "/phantomtouch/touch, /phantomtouch/contact/{id} or /phantomtouch/stop",
            )

    def _receivers(self, sender: Sender, now_s: float) -> None:
        found = self._layout.touches(
            sender.proximity, threshold=self.map.threshold, max_intensity=self.map.max_intensity
        )
        refused: PhantomTouchError | None = None
        for change in sender.tracker.update(found, now_s):
            try:
                self._apply(sender.owner, change)
            except PhantomTouchError as exc:
                sender.tracker.live.pop(change.contact, None)  # tried again on the next value
                refused = exc
        if refused is not None:
            raise refused

    def _apply(self, owner: str, change: Change) -> None:
        if change.kind == "up":
            self.engine.contact_up(owner, change.contact)
        elif change.kind == "down":
            self._down(owner, change.contact, change.x_cm, change.y_cm, change.intensity)
        else:
            self._move(owner, change.contact, change.x_cm, change.y_cm, change.intensity)

    def _down(self, owner: str, contact: str, x_cm: float, y_cm: float, intensity: float) -> None:
        self.engine.contact_down(
            owner,
            contact,
            x_cm,
            y_cm,
            intensity=intensity,
            carrier=self.map.carrier,
            deadline_s=self.map.watchdog_s,
        )

    def _move(self, owner: str, contact: str, x_cm: float, y_cm: float, intensity: float) -> None:
        try:
            self.engine.contact_move(owner, contact, x_cm, y_cm, intensity=intensity)
        except ProtocolError:  # the engine let go of it (a stop, a restart): down again
            self._down(owner, contact, x_cm, y_cm, intensity)

    def _contact(self, owner: str, address: str, args: tuple[Any, ...]) -> None:
        contact = CONTACT_PREFIX + messages.contact_id(address)
        x_cm, y_cm, intensity = messages.contact(address, args)
        if intensity == 0.0:
            self.engine.contact_up(owner, contact)
            return
        held = {
            other: [c for c in contacts if c.startswith(CONTACT_PREFIX)]
            for other, contacts in self.engine.contact_owners(OWNER_PREFIX).items()
        }
        if contact in held.get(owner, ()):
            self._move(owner, contact, x_cm, y_cm, intensity)
            return
        if sum(map(len, held.values())) >= MAX_CONTACTS:
            givers = yielding({other: len(mine) for other, mine in held.items()}, owner)
            if not givers:
                raise messages.BadMessage(
                    "refused",
                    f"{address}: {MAX_CONTACTS} contacts are down (the bridge's most) and no "
                    "other sender holds two more than this one; lift one with intensity 0 first",
                )
            self.engine.contact_up(givers[0], held[givers[0]][0])  # its oldest, faded out
        self._down(owner, contact, x_cm, y_cm, intensity)

    def _play_preset(self, name: str, owner: str) -> None:
        from phantomtouch.renderer import plan, preset

        self.engine.schedule(plan(preset(name), self.engine.device), owner=owner)


def open_socket(host: str, port: int) -> socket.socket:
    """A UDP socket bound to ``(host, port)``.

    Raises
    ------
    DeviceError
        The address cannot be listened on (in use, or not of this machine).
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RECEIVE_BUFFER_BYTES)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise DeviceError(
            f"osc listen={host}:{port}: cannot listen ({exc.strerror}); is another OSC "
            "program using that port? Choose another with --listen"
        ) from exc
    return sock
