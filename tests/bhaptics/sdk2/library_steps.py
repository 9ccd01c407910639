"""Run inside the interpreter that has bHaptics' ``bhaptics_python``: call it step by step.

``python library_steps.py STEPS.json RESULTS.json``: ``STEPS.json`` is a list of
``{"call": NAME, "args": [...], "name": LABEL?, "sleep_s": S?}``; each call is awaited in
order (an argument ``"@LABEL"`` is the result of the step of that label), then the step
sleeps ``sleep_s``. ``RESULTS.json`` gets one ``{"call", "name", "sent_s", "done_s",
"result"}`` per step, times from ``time.monotonic()`` (the machine's clock, the server's
too); a call that raises records ``{"error": ...}``. The library prints its own debug
lines to stdout: send stdout to a log. No project code: this file runs under the library's
interpreter alone.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time

import bhaptics_python


async def run(steps: list[dict], results_path: str) -> None:
    results: list[dict] = []
    by_name: dict[str, object] = {}
    for step in steps:
        args = [
            by_name[a[1:]] if isinstance(a, str) and a.startswith("@") else a for a in step["args"]
        ]
        sent_s = time.monotonic()
        try:
            result = await getattr(bhaptics_python, step["call"])(*args)
        except Exception as exc:  # the library raises its own types (RustPanic)
            result = {"error": f"{type(exc).__name__}: {exc}"}
        done_s = time.monotonic()
        if "name" in step:
            by_name[step["name"]] = result
        results.append(
            {
                "call": step["call"],
                "name": step.get("name"),
                "sent_s": sent_s,
                "done_s": done_s,
                "result": result,
            }
        )
        with open(results_path, "w", encoding="utf-8") as file:
            json.dump(results, file)
        await asyncio.sleep(step.get("sleep_s", 0.0))


if __name__ == "__main__":
    with open(sys.argv[1], encoding="utf-8") as file:
        asyncio.run(run(json.load(file), sys.argv[2]))
