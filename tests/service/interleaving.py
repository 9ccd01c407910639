"""How long another thread waits while a large document is read, measured in an
interpreter of its own (``python -m tests.service.interleaving``): a test process holds
threads of earlier tests that would take turns too. Prints one JSON object: for each
reader, ``[longest wait, the read's length]`` in seconds, both read with the collector
held, as the service reads a large message. The collector's pass over the document when
the hold ends (about 0.1 s for 7 MB kept) is not the read's and is left out: the service
lets go of a refused message before its hold ends.
"""

from __future__ import annotations

import itertools
import json
import threading
import time
from collections.abc import Callable
from typing import Any

from phantomtouch.service.json_slices import collector_held, read_json
from tests.bhaptics.player_client import frame_submits


def longest_wait(read: Callable[[str], Any], text: str) -> tuple[float, float]:
    """The longest time a second thread waited between two of its turns while
    ``read(text)`` ran in this one, and how long that read took (s)."""
    turns: list[float] = []
    done = False

    def other() -> None:
        while not done:  # a turn: one sleep, one taking of the interpreter
            turns.append(time.perf_counter())
            time.sleep(0.0005)

    thread = threading.Thread(target=other)
    thread.start()
    while not turns:
        time.sleep(0.001)
    with collector_held():  # the read's own holds: its collector pass comes after
        began = time.perf_counter()
        try:
            document = read(text)  # kept until the clock is read: freeing it is not the read
        finally:
            ended = time.perf_counter()
            done = True
            thread.join()
        del document
    during = [began, *(t for t in turns if began < t < ended), ended]
    return max(b - a for a, b in itertools.pairwise(during)), ended - began


def main() -> None:
    text = frame_submits(20_000)
    readers: dict[str, Callable[[str], Any]] = {"json.loads": json.loads, "read_json": read_json}
    print(json.dumps({name: longest_wait(read, text) for name, read in readers.items()}))


if __name__ == "__main__":
    main()
