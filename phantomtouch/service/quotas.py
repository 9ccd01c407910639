"""Fair shares of the engine's voices: what each client holds, and the refusal past it.

The engine admits touches until its voices are full, first come first served: one
client could take every voice (64 touches of two hours each) and leave every other
client ``busy`` for hours. The server therefore keeps, per client, the touches it
scheduled and the server time each one ends, and refuses (429 ``quota``, naming the
quota) a touch that would take the client past

- ``voices_per_client`` touches scheduled or playing at once, or
- ``max_voice_seconds_per_client`` seconds still to play, summed over its touches: a
  long touch counts by the time it holds, not only as one.

A client is a WebSocket connection (its owner id) or, over HTTP, the client's address.
Touches stopped early (``DELETE /jobs``, ``/stop``) keep their place in the ledger until
the client next reaches a quota; then the ledger asks the engine which of them are over.
Live contacts are counted by the WebSocket session itself (``max_contacts_per_connection``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

from phantomtouch.service.errors import QuotaError


@dataclass
class Hold:
    """One touch of one client: its job (None while being scheduled) and when it ends."""

    client: str
    end_s: float
    job_id: str | None = None


class VoiceLedger:
    """The touches each client holds, in server time (``engine.server_time_s()``).

    Parameters
    ----------
    voices_per_client : int, >= 1
        Touches one client may have scheduled or playing at once.
    voice_seconds_per_client : float, > 0
        Seconds of touch still to play one client may hold.
    """

    def __init__(self, voices_per_client: int, voice_seconds_per_client: float) -> None:
        self.voices_per_client = voices_per_client
        self.voice_seconds_per_client = voice_seconds_per_client
        self._holds: dict[str, list[Hold]] = {}
        self._lock = threading.Lock()

    def holding(self, client: str, now_s: float) -> tuple[int, float]:
        """The client's touches not over at ``now_s``: how many, and their seconds ahead."""
        with self._lock:
            return self._count(client, now_s)

    def reserve(
        self,
        client: str,
        *,
        now_s: float,
        start_s: float,
        duration_s: float,
        still_playing: Callable[[str], bool],
    ) -> Hold:
        """Hold a place for a touch of ``duration_s`` from ``start_s``, or refuse it.

        ``still_playing(job_id)`` tells whether a job is scheduled or playing; it is asked
        only when the client is at a quota, to forget touches stopped early.

        Raises
        ------
        QuotaError
            The touch would take the client past one of its quotas (the message names it).
        """
        ahead_s = max(start_s, now_s) + duration_s - now_s
        with self._lock:
            if self._over(client, now_s, ahead_s):
                self._forget_stopped(client, still_playing)
            count, held_s = self._count(client, now_s)
            if count + 1 > self.voices_per_client:
                raise QuotaError(
                    f"quota max_voices_per_client={self.voices_per_client} is used up: this "
                    f"client has {count} touches scheduled or playing; retry when one ends, or "
                    "stop one",
                    field="voices",
                    value=count,
                )
            if held_s + ahead_s > self.voice_seconds_per_client:
                raise QuotaError(
                    f"quota max_voice_seconds_per_client={self.voice_seconds_per_client:g} s: "
                    f"this client's touches hold {held_s:.1f} s still to play and this one "
                    f"would add {ahead_s:.1f} s; long touches count by the time they hold",
                    field="duration_s",
                    value=round(duration_s, 6),
                )
            hold = Hold(client, now_s + ahead_s)
            self._holds.setdefault(client, []).append(hold)
            return hold

    def confirm(self, hold: Hold, job_id: str, end_s: float) -> None:
        """The touch was scheduled as ``job_id``, ending at ``end_s``.

        A touch asked for as soon as possible starts a few milliseconds after the
        reservation; it keeps the end it reserved, so that touches that just fit a quota
        still fit once scheduled.
        """
        with self._lock:
            hold.job_id = job_id
            hold.end_s = min(hold.end_s, end_s)

    def cancel(self, hold: Hold) -> None:
        """The touch was not scheduled after all: give its place back."""
        with self._lock:
            holds = self._holds.get(hold.client, [])
            if hold in holds:
                holds.remove(hold)
            if not holds:
                self._holds.pop(hold.client, None)

    def _current(self, client: str, now_s: float) -> list[Hold]:
        holds = [hold for hold in self._holds.get(client, []) if hold.end_s > now_s]
        if holds:
            self._holds[client] = holds
        else:
            self._holds.pop(client, None)
        return holds

    def _count(self, client: str, now_s: float) -> tuple[int, float]:
        holds = self._current(client, now_s)
        return len(holds), sum(hold.end_s - now_s for hold in holds)

    def _over(self, client: str, now_s: float, ahead_s: float) -> bool:
        count, held_s = self._count(client, now_s)
        return (
            count + 1 > self.voices_per_client or held_s + ahead_s > self.voice_seconds_per_client
        )

    def _forget_stopped(self, client: str, still_playing: Callable[[str], bool]) -> None:
        holds = self._holds.get(client, [])
        kept = [hold for hold in holds if hold.job_id is None or still_playing(hold.job_id)]
        if kept:
            self._holds[client] = kept
        else:
            self._holds.pop(client, None)
