"""A client that sends one message starting something long, says so, then never speaks or
reads again (the test freezes it with SIGSTOP). Run as a process of its own::

    python -m tests.attacks.hung_client KIND TARGET

``KIND`` is an input of :mod:`tests.attacks.inputs` and ``TARGET`` its address (a
WebSocket URL, an HTTP base URL, ``HOST:PORT`` for OSC). It imports nothing of
phantomtouch: it speaks each protocol as a client does. It prints ``playing SECONDS`` once
the message went out (``time.monotonic()``, the server's clock on this machine).
"""

from __future__ import annotations

import sys
import time

from tests.attacks.inputs import INPUT_CLASSES


def main(kind: str, target: str) -> None:
    source = INPUT_CLASSES[kind].hung_source(target)
    source.hold()
    print(f"playing {time.monotonic()}", flush=True)
    time.sleep(3600.0)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
