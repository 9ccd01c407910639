"""A gateway's view of the registry: a watch on the bucket keeps every record in memory.

Listings and lookups are answered from this view and never ask NATS, so a NATS server
that dies (and the registry stream's leader election after it) costs no failed listing:
the view shows what it last knew until the watch delivers again.

Expiry follows the registry's own clock. A record is online while its NATS time stamp
plus its ``ttl_s`` lies ahead of the newest time stamp the view has seen (any node's
heartbeat moves that clock on), so a node that stopped beating drops out when the others'
heartbeats show its TTL ran out, whatever the gateway's own clock says. That clock counts
time in which the registry could take writes. While nothing arrives, the clock runs on
with the gateway's monotonic clock only while the registry answers and has taken no write
the view has not read: when the watch falls silent and is started again, the bucket's
last revision is asked for, and the clock runs from an answer that holds nothing new (no
answer: a failover; a newer revision: the watch does not deliver, say through a server
that has only just come back). So nodes that all died expire a TTL and a few heartbeats
after their last write, while a failover, however long, expires nobody. Once the view
follows the bucket, a rise of the newest time stamp counts as the time the
registry was seen answering meanwhile, and at least one heartbeat: the rest of it the
registry took no write (its stream was electing a leader), so the first nodes whose
heartbeats land after a failover do not make the others look expired. A registry that
does not answer for :data:`UNREACHABLE_S` (its only server is gone) no longer holds the
clock: it runs on from then, and the records expire.

The watch is started again when it has been silent for :data:`SILENT_HEARTBEATS`
heartbeats (its consumer may have lived on the server that died; with no record at all,
every three seconds); the new watch replays the last value of every key.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

from phantomtouch.fleet.records import ArmbandRecord
from phantomtouch.fleet.registry import read_record
from phantomtouch.fleet.startup import Deadline, retried
from phantomtouch.fleet.tasks import cancel_until_done

logger = logging.getLogger("phantomtouch.fleet")

UNREACHABLE_S = 60.0
"""How long the registry's clock stands still while the registry does not answer, s."""
SILENT_HEARTBEATS = 3
"""Heartbeat periods of silence after which the watch is started again."""
FIRST_READ_S = 2.0
"""How long the first read of the bucket waits for each record before it starts over, s."""
REWATCH_PAUSE_S = 0.25
"""Pause between attempts to start the watch again while NATS refuses, s."""


@dataclass
class _Entry:
    record: ArmbandRecord
    clock_s: float
    """Its NATS time stamp on the registry's clock: less the silences counted before it."""
    revision: int


class RegistryView:
    """The registry as last seen through a watch on bucket ``kv``; :meth:`start`, then
    :meth:`close`."""

    def __init__(self, kv: Any) -> None:
        self.kv = kv
        self._entries: dict[str, _Entry] = {}
        self._beats: Counter[float] = Counter()
        """The records' heartbeats, s: how many records hold each."""
        self._newest_created_s = 0.0
        self._newest_received_s = time.monotonic()
        self._answered_s: float | None = None
        """When the registry began answering again in the present silence (monotonic), s;
        None while it does not answer."""
        self._answered_before_s = 0.0
        """How long the registry answered in the present silence before it stopped again, s."""
        self._newest_revision = 0
        """The highest revision the view has read."""
        self._skipped_s = 0.0
        """Time stamps' rises the registry's clock does not count (its silences), s."""
        self._following = False
        self._watcher: Any = None
        self._task: asyncio.Task[None] | None = None
        self._closing = False

    # -- reads ----------------------------------------------------------------------------

    def _silence_counted_s(self) -> float:
        """How much of the present silence counts on the registry's clock, s."""
        now_s = time.monotonic()
        answered_s = self._answered_before_s
        if self._answered_s is not None:
            answered_s += now_s - self._answered_s
        return max(answered_s, now_s - self._newest_received_s - UNREACHABLE_S)

    def _answering(self, answers: bool) -> None:
        """The registry answers with nothing new, or not (module docstring)."""
        if answers and self._answered_s is None:
            self._answered_s = time.monotonic()
        elif not answers and self._answered_s is not None:
            self._answered_before_s += time.monotonic() - self._answered_s
            self._answered_s = None

    def _registry_time_s(self) -> float:
        return self._newest_created_s - self._skipped_s + self._silence_counted_s()

    def lookup(self, armband: str) -> ArmbandRecord | None:
        """The armband's record, or None when it is not online."""
        entry = self._entries.get(armband)
        if entry is None or entry.clock_s + entry.record.ttl_s <= self._registry_time_s():
            return None
        return entry.record

    def online(self) -> list[ArmbandRecord]:
        """Every armband online, by id."""
        now_s = self._registry_time_s()
        return [
            entry.record
            for _, entry in sorted(self._entries.items())
            if entry.clock_s + entry.record.ttl_s > now_s
        ]

    # -- the watch ------------------------------------------------------------------------

    async def start(self, who: str, deadline: Deadline) -> None:
        """Watch the bucket and read every record in it before returning.

        The first read is done when the watch says it has caught up, or when it delivers
        the bucket's last revision as of just before the watch began (or a later one): the
        watch delivers in revision order, so every record there was has been read by then.
        It does not wait for the watch's "caught up" marker alone, which a watch may never
        give while records keep arriving (the nodes' heartbeats).

        Raises
        ------
        FleetJoinError
            The watch could not be started, or the bucket not read, by ``deadline``.
        """
        await retried(who, "read the registry", self._first_watch, deadline)
        self._following = True
        self._task = asyncio.create_task(self._follow())

    async def _first_watch(self) -> None:
        status = await self.kv.status()
        last_revision = status.stream_info.state.last_seq
        await self._rewatch()
        records = 0
        while True:
            try:
                entry = await self._watcher.updates(timeout=FIRST_READ_S)
            except TimeoutError:
                raise TimeoutError(
                    f"the registry watch delivered nothing for {FIRST_READ_S:g} s after "
                    f"{records} records, short of revision {last_revision}"
                ) from None
            if entry is None:
                return
            self._apply(entry)
            records += 1
            if entry.revision >= last_revision:
                return

    async def _rewatch(self) -> None:
        old, self._watcher = self._watcher, None
        if old is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(old.stop(), 1.0)
        self._watcher = await self.kv.watchall()

    def _heartbeat_s(self) -> float:
        """The longest heartbeat of the records held (1 s with none), s."""
        return max(self._beats, default=1.0)

    def _silence_s(self) -> float:
        return SILENT_HEARTBEATS * self._heartbeat_s()

    async def _follow(self) -> None:
        import nats.errors

        while not self._closing:
            try:
                if self._watcher is None:
                    try:
                        await self._rewatch()
                        status = await self.kv.status()
                    except Exception:
                        self._answering(False)
                        raise
                    self._answering(status.stream_info.state.last_seq <= self._newest_revision)
                entry = await self._watcher.updates(timeout=self._silence_s())
            except (nats.errors.Error, TimeoutError) as exc:
                if self._watcher is not None and self._entries:
                    logger.info("fleet: registry watch silent (%s); watching again", exc)
                self._watcher = None
                await asyncio.sleep(REWATCH_PAUSE_S)
                continue
            if entry is not None:
                self._apply(entry)

    def _apply(self, entry: Any) -> None:
        self._newest_revision = max(self._newest_revision, entry.revision)
        known = self._entries.get(entry.key)
        if known is not None and entry.revision <= known.revision:
            return  # a watch started again replays what the view holds
        created_s = entry.created.timestamp() if entry.created is not None else 0.0
        if created_s > self._newest_created_s:
            if self._following:
                rise_s = created_s - self._newest_created_s
                counted_s = max(self._heartbeat_s(), self._silence_counted_s())
                self._skipped_s += max(0.0, rise_s - counted_s)
            self._newest_created_s = created_s
            self._newest_received_s = time.monotonic()
            self._answered_s = None
            self._answered_before_s = 0.0
        record = None if entry.operation is not None else read_record(entry.value)
        if known is not None:
            self._beats[known.record.heartbeat_s] -= 1
            if not self._beats[known.record.heartbeat_s]:
                del self._beats[known.record.heartbeat_s]
        if record is None or record.armband != entry.key:
            self._entries.pop(entry.key, None)
        else:
            self._entries[entry.key] = _Entry(record, created_s - self._skipped_s, entry.revision)
            self._beats[record.heartbeat_s] += 1

    async def close(self) -> None:
        """Stop following the bucket.

        The follower is cancelled until it has ended (:func:`cancel_until_done`): a
        single cancel left it running under a stream of heartbeats, and this call waiting
        on it for ever.
        """
        self._closing = True
        if self._task is not None:
            await cancel_until_done(self._task)
        if self._watcher is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._watcher.stop(), 1.0)
