"""Stroke the forearm live: one contact moved along the band at frame rate.

    python live_stroke.py --from 1.9 12 --to 1.9 2.4 --speed-cm-s 5

The position is updated at 240 Hz here (a fast hand tracker); the session sends the newest
position once per frame (90 Hz), so nothing queues up.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from phantomtouch_client import ClientError, Session, ws_url


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000", help="the service")
    parser.add_argument("--token", help="the service token (needed off loopback)")
    parser.add_argument("--from", dest="start", nargs=2, type=float, default=[1.9, 12.0])
    parser.add_argument("--to", dest="end", nargs=2, type=float, default=[1.9, 2.4])
    parser.add_argument("--speed-cm-s", type=float, default=5.0, help="stroke speed, cm/s")
    parser.add_argument("--intensity", type=float, default=0.6, help="relative, 0-1")
    args = parser.parse_args(argv)

    (x0, y0), (x1, y1) = args.start, args.end
    duration_s = math.hypot(x1 - x0, y1 - y0) / args.speed_cm_s
    with Session(ws_url(args.url), token=args.token, client_name="live_stroke") as ws:
        finger = ws.contact("finger")
        finger.down(x0, y0, intensity=args.intensity)
        started = time.monotonic()
        while (t := (time.monotonic() - started) / duration_s) < 1.0:
            finger.move(x0 + (x1 - x0) * t, y0 + (y1 - y0) * t)
            time.sleep(1 / 240)
        finger.move(x1, y1)
        finger.up()
        print(f"stroked {duration_s:.2f} s; round trip {1000 * (ws.rtt_s or 0):.1f} ms")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ClientError as exc:  # the service is down or refused: one line, not a traceback
        sys.exit(f"{sys.argv[0]}: {exc}")
