"""The OSC bridge: a UDP socket, its receive thread, and what each message does.

One thread receives datagrams, takes them apart (:mod:`~phantomtouch.osc.packets`, which
reads each message with python-osc) and handles each message at once, in arrival order:
receiver proximities become live contacts (:mod:`~phantomtouch.osc.receivers`),
``/phantomtouch/...`` messages touch, move, lift, play and stop
(:mod:`~phantomtouch.osc.messages`). The bridge is a protocol translation over the
admission (:mod:`phantomtouch.service.admission`, its ``osc`` row): each sender
(``HOST:PORT``) is a source with a handle (:mod:`~phantomtouch.osc.senders`), which checks
its messages' rate (its own, and its host's together), renews its owner on each of its
messages, holds its contacts in the engine's front with the map's ``watchdog_s`` as
their deadline, and plays its touches through the one touch path (quota first, the plan
cache, a stop voiding what came before it). Bundles are taken apart and their messages
applied on arrival; their time tags are ignored (python-osc's own dispatcher would sleep
until a future time tag, which lets one datagram stall the bridge, and drops unparsable
datagrams without counting them, hence the loop here); a datagram carrying more messages
than the row's ``max_work`` is dropped whole.

Safety: every datagram and message is checked and a bad one dropped, counted
(:class:`~phantomtouch.osc.counters.OscCounters`) and logged in one line, at most one per
reason every :data:`LOG_INTERVAL_S`. The bridge keeps no contact state: a sender's
silence for ``watchdog_s`` releases its contacts -- by the front's deadline thread, so also
when this thread is gone -- and closing the bridge closes every sender. Contacts are shared
by the engine's fair-share rule, first among hosts, then among one host's ports
(:mod:`phantomtouch.engine.shares`): opening more source ports buys a program nothing.
The receive thread is supervised: should it die anyway, the bridge's contacts are released
at once and a new thread started (:meth:`OscBridge.health`). A contact that the engine let
go of meanwhile (``POST /stop``, an engine restart, its deadline) touches down again on its
sender's next message.
"""

from __future__ import annotations

import collections
import logging
import socket
import threading
import time
from typing import Any, Final

import numpy as np
from pydantic import ValidationError

from phantomtouch.errors import (
    DeviceError,
    ParameterError,
    PhantomTouchError,
    ProtocolError,
    install_hint,
)
from phantomtouch.osc import messages
from phantomtouch.osc.counters import OscCounters
from phantomtouch.osc.mapping import ReceiverMap
from phantomtouch.osc.receivers import Change, ContactTracker, ReceiverLayout
from phantomtouch.osc.senders import Receivers
from phantomtouch.schema import describe_validation_error
from phantomtouch.service.admission import Admission, Arrival, Handle, principal_for
from phantomtouch.service.flood import LimitedLog
from phantomtouch.service.models import AnyTouch, NamedTouch, PresetTouch
from phantomtouch.service.running import InputHealth
from phantomtouch.service.thread_priority import raise_thread_priority

try:
    from phantomtouch.osc.packets import BadDatagram, messages_of
except ImportError as exc:  # pragma: no cover - the osc extra is missing
    raise ImportError(f"OSC input needs python-osc, the osc extra: {install_hint('osc')}") from exc

logger = logging.getLogger("phantomtouch.osc")

INPUT: Final = "osc"
"""The input's name in ``/health`` and its kind at the admission."""
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
    """Receives OSC on ``host:port`` and drives the engine through ``admission``.

    Parameters
    ----------
    admission : Admission
        The service's admission; its ``osc`` row (rates, contacts per sender, senders
        kept, the work of one datagram) applies, with the map's ``watchdog_s`` as the
        deadline (the bridge sets it in the row).
    receiver_map : ReceiverMap
        The receivers and how they become contacts.
    host, port : str, int
        Where to listen (UDP); port 0 picks a free one (see :attr:`address`).
    record_latency : bool
        Keep each datagram's receipt-to-engine time in :attr:`latencies_s` (benchmarks).
    """

    def __init__(
        self,
        admission: Admission,
        receiver_map: ReceiverMap,
        *,
        host: str = "127.0.0.1",
        port: int = 9001,
        record_latency: bool = False,
    ) -> None:
        self.admission = admission
        self.map = receiver_map
        self.counters = OscCounters()
        self.watchdog_releases = 0
        self.latencies_s: collections.deque[float] | None = (
            collections.deque(maxlen=_LATENCIES) if record_latency else None
        )
        admission.set_policy(admission.policy(INPUT).replace(deadline_s=receiver_map.watchdog_s))
        self._index = {r.address: i for i, r in enumerate(receiver_map.receiver)}
        self._layout = ReceiverLayout(
            np.array([(r.x_cm, r.y_cm) for r in receiver_map.receiver]),
            receiver_map.cluster_gap_cm,
        )
        self._senders: dict[str, Receivers] = {}
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
        front says); any thread."""
        return sorted(c for h in self.admission.handles(INPUT) for c in h.contacts())

    def _released(self, owner: str, contacts: tuple[str, ...], reason: str) -> None:
        """The front let go of contacts of a sender (any thread): count a watchdog
        release."""
        if reason == "watchdog":
            self.watchdog_releases += 1

    def start(self) -> None:
        """Start the receive thread (in the caller's thread)."""
        self.admission.engine.prepare_carrier(self.map.carrier)
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
        self._senders.clear()
        self.admission.close_all(INPUT, "closed")

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
            self._datagram(data, peer, time.monotonic())
            if self.latencies_s is not None:
                self.latencies_s.append(time.perf_counter() - received_s)

    def _datagram(self, data: bytes, peer: tuple[str, int], now_s: float) -> None:
        try:
            found = messages_of(data)
        except BadDatagram as exc:
            self._drop(exc.reason, f"a datagram of {len(data)} bytes: {exc}")
            return
        sender = self._sender(peer, now_s)
        try:
            sender.handle.check_work(len(found), field="messages")
        except ParameterError as exc:
            self._drop("refused", f"{sender.handle.source}: {exc}")
            return
        for k, (address, args) in enumerate(found):
            verdict = sender.handle.receive(len(data) if k == 0 else 0, now_s=now_s)
            if verdict.arrival is None:
                self._drop("flood", verdict.reason)
                continue
            try:
                self._handle(sender, address, args, verdict.arrival, now_s)
            except messages.BadMessage as exc:
                self._drop(exc.reason, str(exc))
            except PhantomTouchError as exc:
                self._drop("refused", str(exc))
            except Exception as exc:  # the loop (and its watchdog) must outlive any message
                self._drop("failed", f"{address[:64]}: {type(exc).__name__}: {exc}")
            else:
                self.counters.count("accepted")

    def _sender(self, peer: tuple[str, int], now_s: float) -> Receivers:
        """The sender at ``peer`` (an IPv6 peer's flow and scope fields are ignored): its
        handle, opened at the admission if new (a sender that yields its slot to a
        newcomer is forgotten here, its contacts released by the admission)."""
        source = f"{peer[0]}:{peer[1]}"
        handle = self.admission.open(
            INPUT,
            source,
            principal=principal_for(INPUT, host=peer[0]),
            on_yield=lambda _reason: self._forget(source),
            now_s=now_s,
        )
        sender = self._senders.get(source)
        if sender is None or sender.handle is not handle:
            handle.on_released(self._released)
            sender = Receivers(
                handle, [0.0] * len(self._index), ContactTracker(self.map.smoothing_s)
            )
            self._senders[source] = sender
        return sender

    def _drop(self, reason: str, message: str) -> None:
        self.counters.count(reason)
        self._log.warning(reason, f"osc: dropped ({reason}): {message}")

    def _forget(self, source: str) -> None:
        """The sender at ``source`` yielded its slot (the receive thread)."""
        self._senders.pop(source, None)

    def _release_all(self, reason: str) -> None:
        """Forget the smoothing state and release every contact of every sender,
        published with ``reason`` (the receive thread, or the one restarting it)."""
        for sender in list(self._senders.values()):
            sender.forget()
        for handle in self.admission.handles(INPUT):
            handle.release(reason)

    # -- messages -------------------------------------------------------------------------

    def _handle(
        self,
        sender: Receivers,
        address: str,
        args: tuple[Any, ...],
        arrival: Arrival,
        now_s: float,
    ) -> None:
        index = self._index.get(address)
        if index is not None:
            sender.proximity[index] = messages.proximity(address, args)
            self._receivers(sender, now_s)
        elif address.startswith(messages.CONTACT_PREFIX):
            self._contact(sender.handle, address, args)
        elif address == messages.TOUCH:
            request = touch_request(messages.touch_name(address, args))
            sender.handle.play_now(request, arrival=arrival)
        elif address == messages.STOP:
            messages.no_arguments(address, args)
            for each in self._senders.values():
                each.forget()
            self.admission.stop_all()
        else:
            raise messages.BadMessage(
                "unknown_address",
                f"address={address!r} is neither a receiver of the map nor "
                "/phantomtouch/touch, /phantomtouch/contact/{id} or /phantomtouch/stop",
            )

    def _receivers(self, sender: Receivers, now_s: float) -> None:
        found = self._layout.touches(
            sender.proximity, threshold=self.map.threshold, max_intensity=self.map.max_intensity
        )
        handle = sender.handle
        sender.tracker.keep_only(handle.contacts())
        refused: PhantomTouchError | None = None
        for change in sender.tracker.update(found, now_s):
            try:
                self._apply(handle, change)
            except PhantomTouchError as exc:
                sender.tracker.keep_only(handle.contacts())  # tried again on the next value
                refused = exc
        if refused is not None:
            raise refused

    def _apply(self, handle: Handle, change: Change) -> None:
        if change.kind == "up":
            handle.up(change.contact)
        elif change.kind == "down":
            self._down(handle, change.contact, change.x_cm, change.y_cm, change.intensity)
        else:
            self._move(handle, change.contact, change.x_cm, change.y_cm, change.intensity)

    def _down(
        self, handle: Handle, contact: str, x_cm: float, y_cm: float, intensity: float
    ) -> None:
        handle.down(contact, x_cm, y_cm, intensity=intensity, carrier=self.map.carrier)

    def _move(
        self, handle: Handle, contact: str, x_cm: float, y_cm: float, intensity: float
    ) -> None:
        try:
            handle.move(contact, x_cm, y_cm, intensity=intensity)
        except ProtocolError:  # the engine let go of it (a stop, a restart): down again
            self._down(handle, contact, x_cm, y_cm, intensity)

    def _contact(self, handle: Handle, address: str, args: tuple[Any, ...]) -> None:
        contact = CONTACT_PREFIX + messages.contact_id(address)
        x_cm, y_cm, intensity = messages.contact(address, args)
        if intensity == 0.0:
            handle.up(contact)
        else:
            self._move(handle, contact, x_cm, y_cm, intensity)


def touch_request(name: str) -> AnyTouch:
    """The touch request ``/phantomtouch/touch NAME`` makes: a name with a ``/`` is a preset
    (``exp2/curved``), any other a stored pattern.

    Raises
    ------
    ParameterError
        The name is not one a touch request takes (the message names it).
    """
    try:
        return PresetTouch(preset=name) if "/" in name else NamedTouch(stored=name)
    except ValidationError as exc:
        raise ParameterError(f"/phantomtouch/touch: {describe_validation_error(exc)}") from exc


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
