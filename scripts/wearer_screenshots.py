"""Take the screenshots of docs/wearer.md from the real page.

Starts ``phantomtouch serve`` on a free loopback port (null output, a temporary library),
opens the page in Debian's Chromium through Playwright, walks the wearer procedure with a
simulated wearer (fixed sensitivities, no noise) and saves the wearer panel at each step
as ``docs/wearer/<step>.png``. Run from the checkout:

    .venv/bin/python scripts/wearer_screenshots.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from phantomtouch import DeviceProfile  # noqa: E402
from tests.support.live_server import LiveServer  # noqa: E402

OUT = ROOT / "docs" / "wearer"
CHROMIUM = "/usr/bin/chromium"
VIEWPORT = {"width": 1280, "height": 900}
SENSITIVITY_DB = np.array([0.0, -2.0, 1.5, 3.0, -1.0, 0.5, -18.0, 2.5])
"""How much stronger than measured the simulated wearer feels each actuator, dB."""
POSITIONS = np.array([[a.x_cm, a.y_cm] for a in DeviceProfile.default().actuators])
NAME = "participant-07"


def actuator(touch: dict[str, Any]) -> int:
    point = np.array(touch["path"]["points_cm"][0])
    return int(np.argmin(np.linalg.norm(POSITIONS - point, axis=1)))


def felt_db(touch: dict[str, Any], applied_db: np.ndarray) -> float:
    k = actuator(touch)
    return float(touch["level_db"] + SENSITIVITY_DB[k] + applied_db[k])


def shoot(page: Any, step: str) -> None:
    """The wearer panel as a PNG of at most 64 colours (a few tens of KiB)."""
    from PIL import Image  # matplotlib's dependency (the plot extra)

    path = OUT / f"{step}.png"
    page.locator(".wearer-panel").screenshot(path=str(path))
    with Image.open(path) as shot:
        small = shot.convert("RGB").quantize(colors=64)
    small.save(path, optimize=True)
    print(f"{path.relative_to(ROOT)}: {path.stat().st_size // 1024} KiB")


def answer_until(page: Any, touches: list[dict[str, Any]], count: int | None) -> None:
    """Answer matching questions (``count`` of them, or until the run ends)."""
    answered = 0
    while count is None or answered < count:
        page.wait_for_function(
            """() => {
                const trial = document.getElementById('wearer-trial');
                return trial.dataset.done === 'match' || trial.dataset.state === 'asking';
            }"""
        )
        if page.get_attribute("#wearer-trial", "data-done") == "match":
            return
        asked = page.get_attribute("#wearer-trial", "data-question")
        first, second = touches[-2:]
        stronger = felt_db(first, np.zeros(8)) >= felt_db(second, np.zeros(8))
        page.click("#wearer-first" if stronger else "#wearer-second")
        page.wait_for_function(
            f"""() => document.getElementById('wearer-trial').dataset.question !== '{asked}'
                || document.getElementById('wearer-trial').dataset.done === 'match'"""
        )
        answered += 1


def locate(page: Any, touches: list[dict[str, Any]], applied_db: np.ndarray) -> None:
    """Click where each phantom of a localisation check is felt (the felt intensities'
    centroid); the first question is left on screen for a screenshot first."""
    from phantomtouch.renderer.gains import gains_for_points
    from phantomtouch.renderer.geometry import Geometry

    geometry = Geometry.for_device(DeviceProfile.default())
    for _ in range(6):
        page.wait_for_selector("#wearer-trial[data-state='locating']")
        asked = page.get_attribute("#wearer-trial", "data-question")
        point = np.array(touches[-1]["path"]["points_cm"], dtype=float)
        gains, _ = gains_for_points(geometry, point, law="power", mode="2d")
        intensity = (gains[0] * 10 ** ((SENSITIVITY_DB + applied_db) / 20)) ** 2
        felt = intensity @ POSITIONS / intensity.sum()
        x, y = page.evaluate(
            """([x, y]) => {
                const svg = document.getElementById('wearer-picture');
                const p = new DOMPoint(y, x).matrixTransform(svg.getScreenCTM());
                return [p.x, p.y];
            }""",
            [float(felt[0]), float(felt[1])],
        )
        page.mouse.click(x, y)
        page.wait_for_function(
            f"""() => document.getElementById('wearer-trial').dataset.question !== '{asked}'
                || document.getElementById('wearer-trial').dataset.state === 'idle'"""
        )


def main() -> None:
    from playwright.sync_api import sync_playwright

    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as folder:
        server = LiveServer(Path(folder) / "library.db").start()
        try:
            with sync_playwright() as playwright:
                browser: Any = playwright.chromium.launch(
                    executable_path=CHROMIUM, args=["--headless", "--no-sandbox"]
                )
                page = browser.new_page(viewport=VIEWPORT)
                touches: list[dict[str, Any]] = []
                page.on(
                    "request",
                    lambda r: (
                        touches.append(json.loads(r.post_data))
                        if r.method == "POST" and r.url.endswith("/touch")
                        else None
                    ),
                )
                page.goto(f"{server.url}/")
                page.wait_for_selector("body[data-ready=true]")
                # The status bar stays on top while the page scrolls: not over the panel.
                page.add_style_tag(content=".topbar { position: static !important; }")
                page.locator(".wearer-panel").scroll_into_view_if_needed()
                page.fill("#wearer-name", NAME)
                shoot(page, "1-name")
                page.fill("#wearer-duration", "0.05")
                page.click("#wearer-match")
                answer_until(page, touches, 11)
                page.wait_for_selector("#wearer-trial[data-state='asking']")
                page.fill("#wearer-duration", "0.25")  # the default, as a user sees it
                shoot(page, "2-trial")
                page.click("#wearer-cancel")
                page.wait_for_selector("#wearer-trial[data-state='idle']")
                shoot(page, "3-stopped")
                page.fill("#wearer-duration", "0.05")
                page.click("#wearer-match")
                answer_until(page, touches, None)
                page.wait_for_selector("#wearer-trial[data-done='match'][data-state='idle']")
                page.fill("#wearer-duration", "0.25")
                shoot(page, "4-done")
                page.click("#wearer-check")
                page.wait_for_selector("#wearer-trial[data-state='locating']")
                shoot(page, "5-locating")
                locate(page, touches, np.zeros(8))
                page.click("#wearer-apply")
                page.wait_for_selector(f"#wearer-in-force[data-name='{NAME}']")
                active = page.evaluate("() => fetch('/wearer').then((r) => r.json())")
                page.click("#wearer-check")
                locate(page, touches, np.array(active["offsets_db"]))
                page.wait_for_selector("#wearer-compare:not(:empty)")
                shoot(page, "6-compare")
                browser.close()
        finally:
            server.stop()


if __name__ == "__main__":
    main()
