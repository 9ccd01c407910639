"""Clip import (``.ahap``) against ``json.loads`` of the same file, in the same run.

Each file is read by :func:`phantomtouch.clips.parse_clip` (JSON, validation, the
envelopes) and, as the yardstick, by ``json.loads``; both times are the best of
``--runs``. The rows grow the number of events so that the ratio shows whether import
time stays linear in the file (it stays near a constant multiple of ``json.loads``):

- ``continuous N``: N sequential continuous events with attack and release, intensity
  alternating (refused beyond 25,000 events: more than 100,000 breakpoints, named);
- ``transients N``: N transient events;
- ``16 MB``: a file just under the 16 MB limit of continuous events with every event
  parameter set (refused, named: its envelope would have more than 100,000 breakpoints).

``parse_clip`` of a file with its suffix validates the JSON bytes in pydantic-core
straight into plain dicts (:mod:`phantomtouch.clips.ahap_schema`), so the import ratio
stays near that of the clip's own model.

Run: ``python benchmarks/bench_clips.py [--runs 3] [--json]``. Targets (issue 22):
100,000 events under 2 s and a 16 MB file under 5 s.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

from phantomtouch.clips import parse_clip
from phantomtouch.clips.load import MAX_FILE_BYTES
from phantomtouch.errors import ParameterError

_PARAMETERS = ("HapticIntensity", "HapticSharpness", "AttackTime", "ReleaseTime", "DecayTime")


def continuous(events: int, *, every_parameter: bool = False) -> dict[str, Any]:
    pattern = []
    for i in range(events):
        values = {
            "HapticIntensity": 0.5 + 0.4 * (i % 2),
            "HapticSharpness": 0.3,
            "AttackTime": 0.001,
            "ReleaseTime": 0.001,
            "DecayTime": 0.0,
        }
        names = _PARAMETERS if every_parameter else _PARAMETERS[:3]
        pattern.append(
            {
                "Event": {
                    "Time": round(i * 0.005, 6),
                    "EventType": "HapticContinuous",
                    "EventDuration": 0.004,
                    "EventParameters": [
                        {"ParameterID": n, "ParameterValue": values[n]} for n in names
                    ],
                }
            }
        )
    return {"Version": 1.0, "Pattern": pattern}


def transients(events: int) -> dict[str, Any]:
    return {
        "Version": 1.0,
        "Pattern": [
            {
                "Event": {
                    "Time": round(i * 0.005, 6),
                    "EventType": "HapticTransient",
                    "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 0.5}],
                }
            }
            for i in range(events)
        ],
    }


def sixteen_mb() -> bytes:
    low, high = 1_000, 400_000
    while high - low > 100:
        middle = (low + high) // 2
        size = len(json.dumps(continuous(middle, every_parameter=True)))
        low, high = (middle, high) if size <= MAX_FILE_BYTES else (low, middle)
    return json.dumps(continuous(low, every_parameter=True)).encode()


def best_s(run: Callable[[], Any], runs: int) -> float:
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        run()
        times.append(time.perf_counter() - started)
    return min(times)


def row(name: str, data: bytes, runs: int) -> dict[str, Any]:
    def imported() -> str:
        try:
            clip = parse_clip(data, suffix=".ahap")
        except ParameterError as exc:
            return f"refused: {str(exc)[:90]}"
        return f"{len(clip.amplitude)} amplitude points, {len(clip.transients)} transients"

    outcome = imported()
    import_s = best_s(imported, runs)
    json_s = best_s(lambda: json.loads(data), runs)
    return {
        "file": name,
        "mb": len(data) / 1e6,
        "import_s": import_s,
        "json_loads_s": json_s,
        "ratio": import_s / json_s,
        "outcome": outcome,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    files: list[tuple[str, Callable[[], bytes]]] = [
        *(
            (f"continuous {n:,}", lambda n=n: json.dumps(continuous(n)).encode())
            for n in (1_000, 10_000, 25_000, 100_000)
        ),
        *(
            (f"transients {n:,}", lambda n=n: json.dumps(transients(n)).encode())
            for n in (10_000, 100_000)
        ),
        ("16 MB", sixteen_mb),
    ]
    rows = [row(name, make(), args.runs) for name, make in files]
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{'file':<20} {'MB':>6} {'import s':>9} {'json s':>8} {'ratio':>6}  outcome")
    for r in rows:
        print(
            f"{r['file']:<20} {r['mb']:6.2f} {r['import_s']:9.3f} {r['json_loads_s']:8.3f} "
            f"{r['ratio']:6.1f}  {r['outcome']}"
        )


if __name__ == "__main__":
    main()
