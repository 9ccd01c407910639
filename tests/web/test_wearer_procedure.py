"""The wearer procedure in the page, answered by a simulated wearer.

The simulated wearer feels actuator ``k`` (output channel ``k + 1``) ``SENSITIVITY_DB[k]``
stronger than an accelerometer measures (drawn within ±6 dB, seeded). It judges which of
two intervals was stronger by a cumulative normal psychometric function of the felt level
difference, ``P(first) = LAPSE / 2 + (1 - LAPSE) * Phi((L1 - L2) / SLOPE_DB)``, and feels a
phantom at the centroid of the actuators' felt intensities (felt amplitude squared: with
the power law and equal sensitivity that is the intended point). What it is played it
reads from the page's own ``POST /touch`` requests; what the output stage adds it reads
from the service (``/health`` names the profile, ``/wearers/{name}`` its offsets).

The page matches every actuator against actuator 1 and stores the profile; a second
service started on the same library with ``--wearer`` applies it. The localisation check
runs on both: biased without the profile, within 0.5 cm with it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from phantomtouch import DeviceProfile
from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.geometry import Geometry
from tests.support.live_server import LiveServer
from tests.web.support import VIEWPORT, ConsoleErrors, screenshot

SEED = 25
SLOPE_DB = 1.0
"""Standard deviation of the cumulative normal psychometric function, dB."""
LAPSE = 0.02
"""Probability of a random answer on a trial."""
SENSITIVITY_DB = np.random.default_rng(SEED).uniform(-6.0, 6.0, 8)
DEVICE = DeviceProfile.default()
POSITIONS = np.array([[a.x_cm, a.y_cm] for a in DEVICE.actuators])
WEARER = "simulated-07"
TRIAL_S = 2 * 0.25 + 0.25 + 1.0
"""The wearer's time per matching trial: two 0.25 s touches, the 0.25 s gap, 1 s to answer."""


class SimulatedWearer:
    def __init__(self, service_url: str, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.touches: list[dict[str, Any]] = []
        health = httpx.get(f"{service_url}/health", timeout=5.0).json()
        self.applied_db = np.zeros(8)
        if "wearer" in health:
            profile = httpx.get(f"{service_url}/wearers/{health['wearer']}", timeout=5.0).json()
            for channel, db in profile["offsets_db"].get(health["wearer_band"], {}).items():
                self.applied_db[int(channel) - 1] = db

    def heard(self, request: Any) -> None:
        if request.method == "POST" and request.url.endswith("/touch"):
            self.touches.append(json.loads(request.post_data))

    def _actuator(self, touch: dict[str, Any]) -> int:
        point = np.array(touch["path"]["points_cm"][0])
        return int(np.argmin(np.linalg.norm(POSITIONS - point, axis=1)))

    def felt_level_db(self, touch: dict[str, Any]) -> float:
        k = self._actuator(touch)
        return 20 * math.log10(touch["intensity"]) + self.applied_db[k] + SENSITIVITY_DB[k]

    def first_was_stronger(self, first: dict[str, Any], second: dict[str, Any]) -> bool:
        if self.rng.random() < LAPSE:
            return bool(self.rng.random() < 0.5)
        difference = self.felt_level_db(first) - self.felt_level_db(second)
        return bool(self.rng.random() < 0.5 * (1 + math.erf(difference / SLOPE_DB / math.sqrt(2))))

    def felt_at(self, touch: dict[str, Any]) -> np.ndarray:
        point = np.array(touch["path"]["points_cm"], dtype=float)
        gains, _ = gains_for_points(Geometry.for_device(DEVICE), point, law="power", mode="2d")
        amplitude = gains[0] * 10 ** ((self.applied_db + SENSITIVITY_DB) / 20)
        intensity = amplitude**2
        return np.asarray(intensity @ POSITIONS / intensity.sum())


@pytest.fixture
def library(tmp_path: Path) -> Path:
    return tmp_path / "library.db"


def _open_page(browser: Any, url: str, console: ConsoleErrors) -> Any:
    context = browser.new_context(viewport=VIEWPORT, accept_downloads=True)
    page = context.new_page()
    page.on("console", lambda m: console.messages.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda error: console.messages.append(f"pageerror: {error}"))
    page.goto(f"{url}/")
    page.wait_for_selector("body[data-ready=true]", timeout=10_000)
    return page


def _question(page: Any, number: int) -> str:
    page.wait_for_selector(f"#wearer-trial[data-question='{number}']", timeout=10_000)
    return str(page.get_attribute("#wearer-trial", "data-state"))


def _match(page: Any, wearer: SimulatedWearer) -> int:
    page.fill("#wearer-name", WEARER)
    page.fill("#wearer-duration", "0.05")  # the page's pace; the wearer's time is TRIAL_S
    page.click("#wearer-match")
    trials = 0
    while True:
        page.wait_for_function(
            f"""() => {{
                const trial = document.getElementById('wearer-trial');
                return trial.dataset.done === 'match' || trial.dataset.question === '{trials + 1}';
            }}"""
        )
        if page.get_attribute("#wearer-trial", "data-done") == "match":
            return trials
        first, second = wearer.touches[-2:]
        first_stronger = wearer.first_was_stronger(first, second)
        page.click("#wearer-first" if first_stronger else "#wearer-second")
        trials += 1


def _check(page: Any, wearer: SimulatedWearer, first_question: int) -> list[tuple[Any, Any]]:
    page.click("#wearer-check")
    picture = page.locator("#wearer-picture")
    x0, y0, w, h = (float(v) for v in str(page.get_attribute("#wearer-picture", "viewBox")).split())
    pairs = []
    for number in range(first_question, first_question + len(DEVICE.triangles or ())):
        assert _question(page, number) == "locating"
        touch = wearer.touches[-1]
        felt = wearer.felt_at(touch)
        box = picture.bounding_box()
        assert box is not None
        page.mouse.click(
            box["x"] + (felt[0] - x0) / w * box["width"],
            box["y"] + (felt[1] - y0) / h * box["height"],
        )
        pairs.append((touch["path"]["points_cm"][0], felt))
    page.wait_for_selector("#wearer-runs tr", timeout=10_000)
    return pairs


def _page_error_cm(page: Any) -> float:
    return float(str(page.get_attribute("#wearer-runs tr:last-child", "data-error-cm")))


@pytest.fixture
def services(library: Path) -> Iterator[list[LiveServer]]:
    started: list[LiveServer] = []
    yield started
    for server in started:
        server.stop()


def test_the_procedure_recovers_the_offsets_and_centres_the_phantom(
    browser: Any, library: Path, services: list[LiveServer], request: pytest.FixtureRequest
) -> None:
    console = ConsoleErrors()
    before = LiveServer(library).start()
    services.append(before)
    wearer = SimulatedWearer(before.url, SEED)
    page = _open_page(browser, before.url, console)
    page.on("request", wearer.heard)
    trials = _match(page, wearer)
    profile = httpx.get(f"{before.url}/wearers/{WEARER}", timeout=5.0).json()
    recovered = np.array([profile["offsets_db"]["sine_100hz"][str(k)] for k in range(1, 9)])
    drawn = SENSITIVITY_DB[0] - SENSITIVITY_DB  # what makes each felt as actuator 1
    minutes = trials * TRIAL_S / 60
    print(f"matching: {trials} trials, {minutes:.1f} min of the wearer's time")
    print(f"drawn offsets {np.round(drawn, 2)}, recovered {np.round(recovered, 2)}")
    assert np.max(np.abs(recovered - drawn)) <= 1.0, (drawn, recovered)
    assert minutes < 5.0, f"{trials} trials take {minutes:.1f} min"

    unfitted = _check(page, wearer, trials + 1)
    error_before = _page_error_cm(page)
    screenshot(page, f"{request.node.name}-before")
    page.context.close()
    before.stop()

    after = LiveServer(library, args=("--wearer", WEARER)).start()
    services.append(after)
    fitted_wearer = SimulatedWearer(after.url, SEED + 1)
    assert np.allclose(fitted_wearer.applied_db, recovered)
    page = _open_page(browser, after.url, console)
    page.on("request", fitted_wearer.heard)
    fitted = _check(page, fitted_wearer, 1)
    error_after = _page_error_cm(page)
    with page.expect_download() as download:
        page.click("#wearer-csv")
    csv = Path(download.value.path()).read_text().splitlines()
    screenshot(page, f"{request.node.name}-after")
    page.context.close()

    print(
        f"localisation error: {error_before:.2f} cm without the profile, "
        f"{error_after:.2f} cm with it"
    )
    for pairs, error in ((unfitted, error_before), (fitted, error_after)):
        mean = np.mean([np.linalg.norm(np.subtract(felt, intended)) for intended, felt in pairs])
        assert error == pytest.approx(mean, abs=0.05)  # the page's figure is the wearer's
    assert error_before > 0.5, f"without the profile the phantom is felt {error_before:.2f} cm off"
    assert error_after <= 0.5, f"with the profile the phantom is felt {error_after:.2f} cm off"
    assert csv[0] == "run,wearer,intended_x_cm,intended_y_cm,felt_x_cm,felt_y_cm,error_cm"
    assert len(csv) == 1 + len(fitted) and all(line.split(",")[1] == WEARER for line in csv[1:])
    assert console.unexpected() == []
