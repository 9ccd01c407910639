"""The fuzz test at length: thousands of schema-valid touches, any seed, never a 5xx.

The check of ``tests/server/test_fuzz.py`` (each body the schema's
:class:`~phantomtouch.TouchPattern` accepts goes to ``POST /render`` for its plan and its
WAV and to ``POST /touch``; every answer is 2xx, or a 4xx naming a field; WAVs finite
within the ceiling) on ``--examples`` bodies drawn with ``--seed``. It prints one row: the
examples, the answers by status, the failures (0 expected) and the time per example
against a yardstick run in the same process (``POST /render`` of a 1 s preset, the
request every example makes at least once).

Run: ``python benchmarks/bench_fuzz.py [--examples 3000] [--seed N] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import seed as with_seed

from phantomtouch import TouchPattern
from phantomtouch.server import create_app
from tests.model_strategies import bodies
from tests.server.test_fuzz import MAX_WAV_S, check_render, check_touch, schema_valid
from tests.support.service import make_settings


def _yardstick_s(client: TestClient, runs: int = 20) -> float:
    best = float("inf")
    for _ in range(runs):
        start = time.perf_counter()
        client.post("/render", json={"preset": "vr/tap"})
        best = min(best, time.perf_counter() - start)
    return best


def fuzz(examples: int, seed: int) -> dict[str, Any]:
    """Run the check on ``examples`` bodies drawn with ``seed``; failures are listed."""
    statuses: Counter[int] = Counter()
    failures: list[str] = []
    with tempfile.TemporaryDirectory() as folder:
        options = make_settings(Path(folder), max_render_duration_s=MAX_WAV_S, max_voices=4096)
        with TestClient(create_app(options)) as client:
            original_post = client.post

            def counted(url: str, **kwargs: Any) -> Any:
                answer = original_post(url, **kwargs)
                statuses[answer.status_code] += 1
                return answer

            client.post = counted

            @with_seed(seed)
            @settings(
                max_examples=examples,
                derandomize=False,
                database=None,
                deadline=None,
                suppress_health_check=list(HealthCheck),
                report_multiple_bugs=True,
            )
            @given(body=bodies(TouchPattern).map(schema_valid))
            def run(body: dict[str, Any]) -> None:
                try:
                    check_render(client, body)
                    check_touch(client, body)
                except AssertionError as exc:
                    failures.append(str(exc)[:500])
                    raise

            start = time.perf_counter()
            try:
                run()
            except Exception as exc:  # a failure is the result, reported below
                failures.append(f"{type(exc).__name__}: {str(exc)[:500]}")
            elapsed = time.perf_counter() - start
            client.post = original_post
            yardstick = _yardstick_s(client)
    return {
        "examples": examples,
        "seed": seed,
        "requests_by_status": dict(sorted(statuses.items())),
        "failures": len(failures),
        "first_failure": failures[0] if failures else None,
        "seconds": round(elapsed, 2),
        "ms_per_example": round(1000 * elapsed / examples, 2),
        "yardstick_ms": round(1000 * yardstick, 3),
        "example_over_yardstick": round(elapsed / examples / yardstick, 1),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--examples", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=None, help="default: a random one")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    seed = args.seed if args.seed is not None else random.SystemRandom().randrange(2**32)
    result = fuzz(args.examples, seed)
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>24}: {value}")
    return 1 if result["failures"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
