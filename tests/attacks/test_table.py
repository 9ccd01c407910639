"""One table of attacks, run against every input: WebSocket, REST, OSC, bHaptics and fleet.

Each input gets its real processes (:mod:`tests.attacks.stands`), the band's signal is
captured (``--output capture:FILE.wav``), and every row of :data:`ROWS` is played against
it in turn, each with the input's own client (:mod:`tests.attacks.inputs`); then every row
is checked on the capture: what the wearer felt, and when. A row's id says what the wearer
must feel; its assertion message says what they felt instead.

The same rule holds for every input (docs/security.md): what a source started ends one
deadline after its last message (a REST client names its touch's length instead), and at
once when it goes; nothing started before a stop is felt after it; no crowd of idle
connections or of minted identities keeps another client off the band, and no message's
work holds it up; bad numbers are refused, and the output stays finite and under the
ceiling.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tests.attacks.inputs import INPUT_CLASSES, Input, WsInput, WsSource
from tests.attacks.stands import Stand, start_stand
from tests.bhaptics.test_standin_live import RELEASE_S, SILENT
from tests.support.clocks import placed

ROOT = Path(__file__).resolve().parents[2]
BLOCK_S = 0.01
"""The band is looked at in blocks this long: "felt throughout" means in every one."""
VICTIM_PLACE = (1.9, 12.0)
ATTACKER_PLACE = (1.9, 2.4)


@dataclass
class Window:
    """A span of server time and what the wearer must feel in it."""

    start_s: float
    end_s: float
    felt: bool
    what: str
    channel: tuple[float, float] | None = None
    """Only the channel loudest in this span counts (where another client's touch was
    felt on its own), None: any."""
    since: dict[str, Any] | None = None
    """The clock that places the span's start (a stop's own answer: the engine's frame at
    the stop), None: the row's clock reads."""


@dataclass
class Played:
    """What a row did: the windows to check, and what went wrong while it ran."""

    windows: list[Window] = field(default_factory=list)
    error: BaseException | None = None
    span: tuple[float, float] = (0.0, 0.0)
    clocks: list[dict[str, Any]] = field(default_factory=list)
    """``GET /clock`` (the engine's frame at a server time) read as the row began, at its
    moments (:func:`mark`) and as it ended."""

    def placed(self, start_s: float, end_s: float) -> tuple[dict[str, Any], dict[str, Any]]:
        """The clocks that place a span (:func:`tests.support.clocks.placed`)."""
        return placed(self.clocks, start_s, end_s)


def mark(stand: Stand, played: Played) -> None:
    """Read the engine's clock at a moment of the row, to place the spans beside it."""
    played.clocks.append(stand.read_clock())


@dataclass
class Row:
    id: str
    """What the wearer must feel (the test id)."""
    run: Callable[[Stand, Input, Played], None]


def settle(stand: Stand) -> None:
    """Everything off, and a moment for the release."""
    httpx.post(f"{stand.url}/stop", timeout=30.0)
    time.sleep(RELEASE_S + 0.3)


def silence(stand: Stand, inp: Input, played: Played) -> None:
    source = inp.source()
    source.hold()
    t = time.monotonic()
    mark(stand, played)
    time.sleep(inp.silence_ends_s + 2.5)
    ends = t + inp.silence_ends_s + inp.transit_s + stand.after_stop_s
    played.windows += [
        Window(t + 0.2, t + 0.4, True, "the held touch"),
        Window(ends, ends + 2.0, False, "the touch of a source silent past its deadline"),
    ]
    source.close()


def hang(stand: Stand, inp: Input, played: Played) -> None:
    client = subprocess.Popen(
        [sys.executable, "-m", "tests.attacks.hung_client", inp.kind, inp.target],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert client.stdout is not None
        line = client.stdout.readline()
        assert line.startswith("playing "), f"the client did not get to play: {line!r}"
        t = float(line.split()[1])
        client.send_signal(signal.SIGSTOP)
        mark(stand, played)
        time.sleep(inp.silence_ends_s + 2.5)
    finally:
        client.kill()
        client.wait()
    ends = t + inp.silence_ends_s + inp.transit_s + stand.after_stop_s
    played.windows += [
        Window(t + 0.2, t + 0.4, True, "the hung client's touch"),
        Window(ends, ends + 2.0, False, "the touch of a client frozen after one message"),
    ]


def close_mid_play(stand: Stand, inp: Input, played: Played) -> None:
    source = inp.source()
    source.hold()
    if inp.close_ends_s == 0.0:
        source.long_score()
    time.sleep(0.6)
    mark(stand, played)
    source.close()
    t = time.monotonic()
    time.sleep(inp.close_ends_s + 2.5)
    ends = t + inp.close_ends_s + inp.transit_s + stand.after_stop_s
    played.windows += [
        Window(t - 0.3, t - 0.1, True, "the touch before the source went"),
        Window(ends, ends + 2.0, False, "the touch of a source that went"),
    ]


def idle_crowd(stand: Stand, inp: Input, played: Played) -> None:
    crowd = [inp.source() for _ in range(inp.slots)]
    for idle in crowd:
        idle.renew()
    time.sleep(0.5)
    try:
        newcomer = inp.source()
        newcomer.hold()
        t = time.monotonic()
        mark(stand, played)
        time.sleep(1.0)
        mark(stand, played)
        newcomer.close()
    finally:
        for idle in crowd:
            idle.close()
    played.windows.append(
        Window(t + 0.3, t + 0.9, True, f"a newcomer's touch beside {inp.slots} idle sources")
    )


def alone(stand: Stand, inp: Input, played: Played) -> tuple[float, float]:
    """A touch at :data:`VICTIM_PLACE` held alone for a moment: the span where it was felt
    on its own, whose loudest channel is the one that tells it from others."""
    probe = inp.source()
    probe.hold(*VICTIM_PLACE, 1.0)
    t = time.monotonic()
    mark(stand, played)
    time.sleep(0.5)
    mark(stand, played)
    probe.close()
    settle(stand)
    return (t + 0.2, t + 0.45)


def minted_identities(stand: Stand, inp: Input, played: Played) -> None:
    own = alone(stand, inp, played)
    crowd = [inp.source(local="127.0.0.2") for _ in range(min(inp.slots, 64))]
    for attacker in crowd:
        attacker.hold(*ATTACKER_PLACE, 0.3)
    time.sleep(0.3)
    victim = inp.source()
    victim.hold(*VICTIM_PLACE, 1.0)
    t = time.monotonic()
    lasts_s = min(2.3, inp.silence_ends_s - 0.2) if inp.kind == "rest" else 2.3
    end = t + lasts_s
    mark(stand, played)
    while time.monotonic() < end:
        for source in (victim, *crowd):
            source.renew()
        time.sleep(0.1)
    mark(stand, played)
    victim.close()
    for attacker in crowd:
        attacker.close()
    played.windows.append(
        Window(
            t + 0.3,
            t + lasts_s - 0.1,
            True,
            f"another client's touch while one host held {len(crowd)} sources",
            own,
        )
    )


class Mover:
    """Another client's contact on the band's ``/ws``, moved at 30 Hz by a thread."""

    def __init__(self, stand: Stand) -> None:
        self.source = WsSource(stand.ws_url)
        self.source.hold(*VICTIM_PLACE, 1.0)
        self._running = True
        self._thread = threading.Thread(target=self._move, daemon=True)
        self._thread.start()

    def _move(self) -> None:
        k = 0
        while self._running:
            k += 1
            self.source.move(VICTIM_PLACE[0], VICTIM_PLACE[1] - 0.05 * (k % 2))
            time.sleep(1 / 30)

    def close(self) -> list[dict[str, Any]]:
        self._running = False
        self._thread.join()
        self.source.close()
        return [m for m in self.source.seen if m.get("type") == "released"]


def huge_work(stand: Stand, inp: Input, played: Played) -> None:
    own = alone(stand, WsInput(stand.ws_url), played)
    mover = Mover(stand)
    time.sleep(0.5)
    mark(stand, played)
    t = time.monotonic()
    source = inp.source()
    for _ in range(2):
        source.huge()
    time.sleep(1.0)
    end = time.monotonic()
    mark(stand, played)
    source.close()
    released = mover.close()
    assert not released, f"the other client's hand was let go of: {released}"
    played.windows.append(
        Window(
            t,
            end,
            True,
            "another client's hand, stroking while one message asked for huge work",
            own,
        )
    )


def stop_url(stand: Stand) -> dict[str, Any]:
    """``POST /stop``; its answer, a clock: the server time it took effect and the engine's
    frame then.

    What follows a stop is placed by that frame. A loaded machine may stall the engine
    between the stop and the next clock read, and placed by that read a window's start
    falls as many frames too early as the stall lasted: inside the stop's release (40 ms
    early put 0.07 FS of it in the window; :mod:`tests.support.clocks`).
    """
    answer: dict[str, Any] = httpx.post(f"{stand.url}/stop", timeout=30.0).json()
    return answer


def stop_during_planning(stand: Stand, inp: Input, played: Played) -> None:
    source = inp.source()
    source.plan_big()
    time.sleep(0.1)
    stopped = stop_url(stand)
    mark(stand, played)
    time.sleep(8.5)
    source.close()
    stop = stopped["server_time_s"]
    played.windows.append(
        Window(
            stop + stand.after_stop_s,
            stop + 8.2,
            False,
            "a touch being planned when the stop came",
            since=stopped,
        )
    )


def stop_during_score(stand: Stand, inp: Input, played: Played) -> None:
    source = inp.source()
    source.long_score()
    time.sleep(1.0)
    mark(stand, played)
    stopped = stop_url(stand)
    mark(stand, played)
    time.sleep(3.0)
    source.close()
    stop = stopped["server_time_s"]
    played.windows += [
        Window(stop - 0.6, stop - 0.1, True, "the long score before the stop"),
        Window(
            stop + stand.after_stop_s,
            stop + 3.0,
            False,
            "the long score after the stop",
            since=stopped,
        ),
    ]


def bad_values(stand: Stand, inp: Input, played: Played) -> None:
    source = inp.source()
    source.bad_values()
    time.sleep(0.5)
    source.close()
    t = time.monotonic()
    mark(stand, played)
    time.sleep(2.0)
    assert httpx.get(f"{stand.url}/health", timeout=10.0).status_code == 200
    ends = t + max(inp.close_ends_s, 1.0) + inp.transit_s + stand.after_stop_s
    played.windows.append(Window(ends, t + 2.0, False, "anything of the bad values"))


ROWS = [
    Row("silence past the deadline: the touch ends", silence),
    Row("hang after one message: the touch ends", hang),
    Row("close mid-play: nothing plays on", close_mid_play),
    Row("crowd of idle connections: a newcomer is felt", idle_crowd),
    Row("crowd of minted identities: another client is felt throughout", minted_identities),
    Row("message carrying huge work: another client is felt throughout", huge_work),
    Row("stop during planning: nothing after the stop", stop_during_planning),
    Row("stop during a long score: nothing after the stop", stop_during_score),
    Row("NaN and huge values: refused, finite, under the ceiling", bad_values),
]


@dataclass
class Table:
    stand: Stand
    inp: Input
    played: dict[str, Played]
    band: Any


@pytest.fixture(scope="module", params=list(INPUT_CLASSES))
def table(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Table]:
    kind = request.param
    stand = start_stand(kind, tmp_path_factory.mktemp(f"attacks-{kind}"))
    inp = INPUT_CLASSES[kind](stand.target)
    played: dict[str, Played] = {}
    try:
        for row in ROWS:
            settle(stand)
            result = played[row.id] = Played()
            mark(stand, result)
            start = time.monotonic()
            try:
                row.run(stand, inp, result)
            except Exception as exc:  # the row fails alone; the others still run
                result.error = exc
            result.span = (start, time.monotonic())
            mark(stand, result)
    finally:
        band = stand.stop()
    yield Table(stand, inp, played, band)


NOT_YET: dict[tuple[str, str], str] = {}
"""Rows an input does not hold yet, and why: each is expected to fail (strictly: a row that
starts to hold fails here until it is taken off this list)."""


@pytest.mark.parametrize("row", ROWS, ids=[row.id for row in ROWS])
def test_attack(table: Table, row: Row, request: pytest.FixtureRequest) -> None:
    played = table.played[row.id]
    kind = table.inp.kind
    gap = NOT_YET.get((kind, row.id))
    if gap is not None:
        request.applymarker(pytest.mark.xfail(reason=f"{kind}: {gap}", strict=True))
    if played.error is not None:
        raise AssertionError(f"{kind}: {row.id}: the attack could not be played") from played.error
    band = table.band
    start, end = played.span
    whole = band.between(start, end, *played.placed(start, end))
    assert np.all(np.isfinite(whole)), f"{kind}: the wearer's band was driven with NaN or Inf"
    ceiling = table.stand.ceiling
    assert float(np.max(np.abs(whole), initial=0.0)) <= ceiling + 1e-6, (
        f"{kind}: the band was driven past its ceiling {ceiling}"
    )
    for window in played.windows:
        loudest: int | None = None
        if window.channel is not None:
            alone_block = band.between(*window.channel, *played.placed(*window.channel))
            assert alone_block.size, f"{kind}: the capture holds nothing of the touch alone"
            loudest = int(np.argmax(np.sum(alone_block**2, axis=0)))
        began, ended = played.placed(window.start_s, window.end_s)
        block = band.between(window.start_s, window.end_s, window.since or began, ended)
        if loudest is not None:
            block = block[:, [loudest]]
        if window.felt:
            frames = max(1, round(BLOCK_S * band.rate_hz))
            usable = len(block) // frames * frames
            assert usable, f"{kind}: the capture holds nothing of {window.what}"
            peaks = np.max(np.abs(block[:usable]), axis=1).reshape(-1, frames).max(axis=1)
            gaps = int(np.sum(peaks <= SILENT))
            assert gaps == 0, (
                f"{kind}: the wearer did not feel {window.what} in {gaps} of {len(peaks)} "
                f"blocks of {BLOCK_S * 1e3:g} ms"
            )
        else:
            felt = float(np.max(np.abs(block), initial=0.0))
            assert felt <= SILENT, f"{kind}: the wearer felt {window.what} at {felt:.2f} FS"
