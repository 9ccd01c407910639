"""Start-up cost of ``import phantomtouch`` against a bare interpreter, same run.

Each measurement is a fresh interpreter (``python -X importtime`` would distort the
times); the yardstick is ``python -c pass``. Reported: best and median wall time of
each, their difference (what the import costs) and the scipy modules the import loads
(the core keeps scipy out; spline paths, custom layouts and analysis load it on use).

``import phantomtouch`` loads its names on first use, so the same is reported for
``from phantomtouch import *``, the whole stable interface (pydantic and numpy).

Run: ``python benchmarks/bench_import.py [--runs N] [--json]``. Target (issue): the
import costs <= 0.3 s.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time


def wall_times(code: str, runs: int) -> list[float]:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True)
        times.append(time.perf_counter() - start)
    return times


def scipy_modules(code: str) -> int:
    """How many scipy modules ``code`` leaves loaded in a fresh interpreter."""
    count = subprocess.run(
        [
            sys.executable,
            "-c",
            f"{code}\nimport sys\nprint(sum(m.startswith('scipy') for m in sys.modules))",
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return int(count.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    bare = wall_times("pass", args.runs)
    loaded = wall_times("import phantomtouch", args.runs)
    whole = wall_times("from phantomtouch import *", args.runs)
    result = {
        "python_c_pass_s": {"best": min(bare), "median": statistics.median(bare)},
        "import_phantomtouch_s": {"best": min(loaded), "median": statistics.median(loaded)},
        "import_cost_s": {
            "best": min(loaded) - min(bare),
            "median": statistics.median(loaded) - statistics.median(bare),
        },
        "whole_interface_cost_s": {
            "best": min(whole) - min(bare),
            "median": statistics.median(whole) - statistics.median(bare),
        },
        "scipy_modules_loaded": scipy_modules("import phantomtouch"),
        "scipy_modules_loaded_by_whole_interface": scipy_modules("from phantomtouch import *"),
        "runs": args.runs,
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    for name in (
        "python_c_pass_s",
        "import_phantomtouch_s",
        "import_cost_s",
        "whole_interface_cost_s",
    ):
        print(
            f"{name:24s} best {result[name]['best']:.3f} s  median {result[name]['median']:.3f} s"
        )
    print(
        f"scipy modules loaded: {result['scipy_modules_loaded']} by the import, "
        f"{result['scipy_modules_loaded_by_whole_interface']} by the whole interface"
    )


if __name__ == "__main__":
    main()
