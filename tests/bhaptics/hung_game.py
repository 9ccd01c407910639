"""A game that hangs: it plays one long frame and one long key, says so, then never speaks
or reads again (the test freezes it with SIGSTOP). Run as a process of its own::

    python -m tests.bhaptics.hung_game ws://127.0.0.1:PORT/v2/feedbacks LENGTH_MS

It imports nothing of phantomtouch. It prints ``playing SERVER_TIME_S`` once the stand-in
answered the submit (``time.monotonic()``, the server's clock on this machine).
"""

from __future__ import annotations

import json
import sys
import time

from websockets.sync.client import connect

from tests.bhaptics.test_standin_live import dot_project


def main(url: str, length_ms: int) -> None:
    with connect(url, compression=None, max_size=None) as ws:
        ws.recv()  # the status on connecting
        ws.send(
            json.dumps(
                {"Register": [{"Key": "long", "Project": dot_project("ForearmR", 0, length_ms)}]}
            )
        )
        ws.recv()
        submit = [
            {"Type": "key", "Key": "long"},
            {
                "Type": "frame",
                "Key": "held",
                "Frame": {
                    "Position": "ForearmL",
                    "DotPoints": [{"Index": 5, "Intensity": 60}],
                    "PathPoints": [],
                    "DurationMillis": length_ms,
                },
            },
        ]
        ws.send(json.dumps({"Register": [], "Submit": submit}))
        ws.recv()
        print(f"playing {time.monotonic()}", flush=True)
        time.sleep(3600.0)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
