"""Play a block of trials in a seeded random order and log when each one played.

    python trial_block.py --presets exp2/central exp2/right exp2/diagonal exp2/curved \
        --repeats 3 --gap-s 2 --log block.csv

Each trial is scheduled on the server clock (``start_at_s``), so the gaps are exact even
if this script is late; the log holds the server's start time and duration of each job.
"""

from __future__ import annotations

import argparse
import csv
import random
import sys
import time

from phantomtouch_client import Client, ClientError


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000", help="the service")
    parser.add_argument("--token", help="the service token (needed off loopback)")
    parser.add_argument("--presets", nargs="+", required=True, help="preset names to play")
    parser.add_argument("--repeats", type=int, default=1, help="times each preset plays")
    parser.add_argument("--gap-s", type=float, default=1.0, help="silence between trials, s")
    parser.add_argument("--seed", type=int, default=0, help="seed of the trial order")
    parser.add_argument("--log", help="CSV file for the trial log (default: stdout)")
    args = parser.parse_args(argv)

    trials = [name for name in args.presets for _ in range(args.repeats)]
    random.Random(args.seed).shuffle(trials)
    out = open(args.log, "w", newline="") if args.log else sys.stdout  # noqa: SIM115
    log = csv.writer(out)
    log.writerow(["trial", "preset", "job_id", "start_at_s", "duration_s"])
    with Client(args.url, token=args.token) as pt:
        start_at_s = pt.clock().server_time_s + 0.2
        for trial, name in enumerate(trials, 1):
            job = pt.touch(preset=name, start_at_s=start_at_s)
            log.writerow([trial, name, job.job_id, f"{job.start_at_s:.6f}", job.duration_s])
            out.flush()
            start_at_s = job.start_at_s + job.duration_s + args.gap_s
            # Schedule the next trial a little before this one ends, never far ahead.
            time.sleep(max(0.0, start_at_s - 0.5 - pt.clock().server_time_s))
    if out is not sys.stdout:
        out.close()
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ClientError as exc:  # the service is down or refused: one line, not a traceback
        sys.exit(f"{sys.argv[0]}: {exc}")
