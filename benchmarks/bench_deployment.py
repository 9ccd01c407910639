"""SDK2 deployments: reading one, and scoring its events, against ``json.loads``, same run.

A game's deployment is read when it connects (``SdkRequestAuthInit``) and when its
workspace is imported; its events are scored when played. Each row is a deployment built
in the Developer Portal's shape (docs/bhaptics.md, "SDK2"), read by
:func:`phantomtouch.clips.deployment.parse_deployment` and, as the yardstick, by
``json.loads`` of the same text; both the best of ``--runs``:

- ``tact N``: N events, each a real arm ``.tact`` file of the corpus (cycled);
- ``audio N x F``: N events of F audio frames (20 ms each) on ``ForearmL``, ``ForearmR``
  and both vest halves, every arm motor changing level every frame (the most points a clip
  can make): what newer deployments carry; 1000 events is the most a deployment may hold.

``score`` is :func:`~phantomtouch.clips.deployment.event_score` of the longest event of
the row (the work of one ``SdkPlay``), best of ``--runs``, beside the same yardstick.

Run: ``python benchmarks/bench_deployment.py [--runs 3] [--json]``.
"""

from __future__ import annotations

import argparse
import base64
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from phantomtouch.clips.deployment import event_score, parse_deployment
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.schema import DeviceProfile

CORPUS = (
    Path(__file__).resolve().parents[1]
    / "tests"
    / "clips"
    / "samples"
    / "tact"
    / "bhaptics-popone-support"
    / "Arm"
)


def frame(levels: list[int]) -> str:
    return base64.b64encode(bytes(levels) + bytes(20 - len(levels))).decode()


def mapping(key: str, tact: Any = None, clip: Any = None) -> dict[str, Any]:
    return {
        "key": key,
        "enable": True,
        "intensity": 100,
        "eventTime": 1000,
        "tactFilePatterns": [] if tact is None else [{"position": "LeftArm", "tactFile": tact}],
        "audioFilePatterns": [] if clip is None else [{"position": "Vest", "clip": clip}],
    }


def portal(mappings: list[dict[str, Any]]) -> str:
    return json.dumps(
        {"status": True, "code": 200, "message": {"name": "bench", "hapticMappings": mappings}}
    )


def tact_deployment(events: int) -> str:
    files = sorted(CORPUS.glob("*.tact"))
    projects = [json.loads(f.read_text(encoding="utf-8-sig"))["project"] for f in files]
    return portal([mapping(f"e{i}", tact=projects[i % len(projects)]) for i in range(events)])


def audio_deployment(events: int, frames: int) -> str:
    ramp = [frame([(k * 2 + m * 7) % 101 for m in range(6)]) for k in range(frames)]
    vest = [frame([(k * 3 + m) % 101 for m in range(20)]) for k in range(frames)]
    clip = {"patterns": {"ForearmL": ramp, "ForearmR": ramp, "VestFront": vest, "VestBack": vest}}
    return portal([mapping(f"e{i}", clip=clip) for i in range(events)])


def best_s(call: Callable[[], object], runs: int) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def row(name: str, text: str, runs: int) -> dict[str, Any]:
    yardstick_s = best_s(lambda: json.loads(text), runs)
    parse_s = best_s(lambda: parse_deployment(text), runs)
    deployment = parse_deployment(text)
    longest = max(deployment.events.values(), key=lambda e: e.length_ms)
    device, arm_map = DeviceProfile.default(), ArmMap()
    score_s = best_s(lambda: event_score(longest, arm_map, device), runs)
    return {
        "row": name,
        "bytes": len(text.encode("utf-8")),
        "events": len(deployment.events),
        "json_loads_s": yardstick_s,
        "parse_s": parse_s,
        "parse_ratio": parse_s / yardstick_s,
        "score_longest_s": score_s,
        "score_ratio": score_s / yardstick_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    DeviceProfile.default()  # its first load is not a deployment's cost
    rows = [
        row("tact 44", tact_deployment(44), args.runs),
        row("tact 500", tact_deployment(500), args.runs),
        row("audio 100x50", audio_deployment(100, 50), args.runs),
        row("audio 1000x10", audio_deployment(1000, 10), args.runs),
    ]
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{'row':14s} {'MB':>6s} {'events':>6s} {'json.loads':>11s} {'parse':>9s} {'ratio':>6s}")
    for r in rows:
        print(
            f"{r['row']:14s} {r['bytes'] / 1e6:6.2f} {r['events']:6d} "
            f"{r['json_loads_s'] * 1e3:9.1f}ms {r['parse_s'] * 1e3:7.1f}ms "
            f"{r['parse_ratio']:6.1f}  score of the longest {r['score_longest_s'] * 1e3:.1f} ms"
        )


if __name__ == "__main__":
    main()
