"""The wearer procedure in the page against a real service, answered by simulated wearers.

The realistic wearer feels actuator ``k`` (output channel ``k + 1``) ``SENSITIVITY_DB[k]``
stronger than an accelerometer measures (drawn within ±6 dB, seeded), except actuator 7,
which is weak: it would need 20 dB more than the reference, beyond the device's ceiling.
It judges which of two intervals was stronger by a cumulative normal psychometric function
of the felt level difference, ``P(first) = LAPSE / 2 + (1 - LAPSE) * Phi((L1 - L2) /
SLOPE_DB)``, and feels a phantom at the centroid of the actuators' felt intensities (felt
amplitude squared: with the power law and equal sensitivity that is the intended point).
What it is played it reads from the page's own ``POST /touch`` requests; what the output
stage adds from the service (``GET /wearer``).

Other wearers answer "reference stronger" throughout (every actuator weaker than the
reference at any level), or at random (seeded), for whole runs; one run is stopped by
closing the page and by Cancel, and resumed. Every run must end with a stored profile
whose offsets lie at or below the ceiling the service names (``GET /device``).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from phantomtouch import DeviceProfile
from phantomtouch.renderer.gains import gains_for_points
from phantomtouch.renderer.geometry import Geometry
from tests.support.live_server import LiveServer
from tests.web.support import VIEWPORT, ConsoleErrors, screenshot, wait_until

SEED = 25
SLOPE_DB = 1.0
"""Standard deviation of the cumulative normal psychometric function, dB."""
LAPSE = 0.02
"""Probability of a random answer on a trial."""
WEAK = 6
"""The weak actuator's index (actuator 7, channel 7)."""
SENSITIVITY_DB = np.random.default_rng(SEED).uniform(-6.0, 6.0, 8)
SENSITIVITY_DB[WEAK] = SENSITIVITY_DB[0] - 20.0
DEVICE = DeviceProfile.default()
POSITIONS = np.array([[a.x_cm, a.y_cm] for a in DEVICE.actuators])
TRIAL_S = 2 * 0.25 + 0.25 + 1.0
"""The wearer's time per matching trial: two 0.25 s touches, the 0.25 s gap, 1 s to answer."""
PROGRESS = re.compile(r"^Trial (\d+) of about (\d+), (~\d+ min left|under a minute left)$")
Answer = Callable[[dict[str, Any], dict[str, Any]], int]
"""Given the trial's two touches, 1 or 2: which the wearer says was stronger."""


class Wearer:
    """What the page plays, heard from its requests; answers as the subclass decides."""

    def __init__(self, service_url: str) -> None:
        self.url = service_url
        self.touches: list[dict[str, Any]] = []

    def heard(self, request: Any) -> None:
        if request.method == "POST" and request.url.endswith("/touch"):
            self.touches.append(json.loads(request.post_data))

    @staticmethod
    def actuator(touch: dict[str, Any]) -> int:
        point = np.array(touch["path"]["points_cm"][0])
        return int(np.argmin(np.linalg.norm(POSITIONS - point, axis=1)))


class SimulatedWearer(Wearer):
    def __init__(self, service_url: str, seed: int) -> None:
        super().__init__(service_url)
        self.rng = np.random.default_rng(seed)
        self.applied_db = np.zeros(8)

    def read_applied(self) -> None:
        """The offsets the output stage adds now (GET /wearer)."""
        active = httpx.get(f"{self.url}/wearer", timeout=5.0).json()
        self.applied_db = np.array(active["offsets_db"], dtype=float)

    def felt_level_db(self, touch: dict[str, Any]) -> float:
        k = self.actuator(touch)
        return float(touch["level_db"] + self.applied_db[k] + SENSITIVITY_DB[k])

    def answer(self, first: dict[str, Any], second: dict[str, Any]) -> int:
        if self.rng.random() < LAPSE:
            return int(self.rng.integers(1, 3))
        difference = self.felt_level_db(first) - self.felt_level_db(second)
        p_first = 0.5 * (1 + math.erf(difference / SLOPE_DB / math.sqrt(2)))
        return 1 if self.rng.random() < p_first else 2

    def felt_at(self, touch: dict[str, Any]) -> np.ndarray:
        point = np.array(touch["path"]["points_cm"], dtype=float)
        gains, _ = gains_for_points(Geometry.for_device(DEVICE), point, law="power", mode="2d")
        amplitude = gains[0] * 10 ** ((self.applied_db + SENSITIVITY_DB) / 20)
        intensity = amplitude**2
        return np.asarray(intensity @ POSITIONS / intensity.sum())


def reference_stronger(first: dict[str, Any], second: dict[str, Any]) -> int:
    """Every actuator is felt weaker than the reference (actuator 1), whatever its level."""
    return 1 if Wearer.actuator(first) == 0 else 2


def at_random(seed: int) -> Answer:
    rng = np.random.default_rng(seed)
    return lambda first, second: int(rng.integers(1, 3))


# --- the page ------------------------------------------------------------------------------


def _open_page(browser: Any, url: str, console: ConsoleErrors, wearer: Wearer) -> Any:
    context = browser.new_context(viewport=VIEWPORT, accept_downloads=True)
    page = context.new_page()

    def logged(message: Any) -> None:
        if message.type == "error":
            console.messages.append(f"{message.text} {message.location.get('url', '')}")

    page.on("console", logged)
    page.on("pageerror", lambda error: console.messages.append(f"pageerror: {error}"))
    page.on("request", wearer.heard)
    page.goto(f"{url}/")
    page.wait_for_selector("body[data-ready=true]", timeout=10_000)
    return page


@pytest.fixture
def console() -> ConsoleErrors:
    console = ConsoleErrors()
    # Looking up a wearer's saved run finds none for a new wearer: a 404 the page expects.
    console.allow(r"status of 404 .*/wearers/[A-Za-z0-9._-]+/run$")
    return console


@pytest.fixture
def services(tmp_path: Path) -> Iterator[Callable[[], LiveServer]]:
    started: list[LiveServer] = []

    def start() -> LiveServer:
        server = LiveServer(tmp_path / "library.db").start()
        started.append(server)
        return server

    yield start
    for server in started:
        server.stop()


def _trial_view(page: Any) -> dict[str, Any]:
    """What the page shows for the question on screen, and whether it is in view."""
    return dict(
        page.evaluate(
            """() => {
                const inView = (id) => {
                    const box = document.getElementById(id).getBoundingClientRect();
                    return box.top >= 0 && box.bottom <= window.innerHeight && box.height > 0;
                };
                const numbers = (selector) => [...document.querySelectorAll(
                    `#wearer-picture ${selector}`)].map((g) => Number(g.dataset.actuator));
                return {
                    progress: document.getElementById('wearer-progress-text').textContent,
                    question: document.getElementById('wearer-trial-text').textContent,
                    lit: numbers('.actuator.lit'),
                    marked: numbers('.actuator.marked'),
                    inView: ['wearer-progress', 'wearer-first', 'wearer-second',
                             'wearer-picture'].every(inView),
                };
            }"""
        )
    )


def _answer(page: Any, wearer: Wearer, answer: Answer, *, stop_after: int | None = None) -> int:
    """Answer the matching questions until the run ends (or ``stop_after`` answers);
    checks every trial's progress line, lit actuator and levels on the way."""
    ceiling_db = httpx.get(f"{wearer.url}/device", timeout=5.0).json()["max_level_db"]
    answered = 0
    # both read at once: read one by one, the page may ask its first question in between
    asked, pending = page.evaluate(
        """() => {
            const trial = document.getElementById('wearer-trial');
            return [Number(trial.dataset.question || 0), trial.dataset.state === 'asking'];
        }"""
    )
    first_number = asked if pending else asked + 1
    while stop_after is None or answered < stop_after:
        try:
            page.wait_for_function(
                f"""() => {{
                    const trial = document.getElementById('wearer-trial');
                    return trial.dataset.done === 'match'
                        || trial.dataset.question === '{first_number + answered}';
                }}"""
            )
        except Exception as exc:  # the page's own line says why the run stopped
            message = page.text_content("#wearer-message")
            raise AssertionError(f"trial {first_number + answered}: {message!r}") from exc
        if page.get_attribute("#wearer-trial", "data-done") == "match":
            break
        view = _trial_view(page)
        first, second = wearer.touches[-2:]
        test = first if Wearer.actuator(second) == 0 else second
        assert PROGRESS.match(view["progress"]), view["progress"]
        assert view["inView"], f"the trial is not in view: {view}"
        assert view["lit"] == [Wearer.actuator(test) + 1] and view["marked"] == [1], view
        assert f"Actuator {view['lit'][0]} (lit)" in view["question"]
        assert all(t["level_db"] <= ceiling_db for t in (first, second)), (first, second)
        assert "intensity" not in first and "intensity" not in second
        page.click("#wearer-first" if answer(first, second) == 1 else "#wearer-second")
        answered += 1
    return answered


def _start(page: Any, name: str) -> None:
    page.fill("#wearer-name", name)
    page.fill("#wearer-duration", "0.05")  # the page's pace; the wearer's time is TRIAL_S
    page.click("#wearer-match")


def _wait_done(page: Any) -> None:
    page.wait_for_selector("#wearer-trial[data-done='match'][data-state='idle']", timeout=20_000)


def _assert_finished_cleanly(page: Any) -> None:
    panel = page.inner_text(".wearer-panel")
    assert "${" not in panel, "a raw template is shown"
    assert page.inner_text("#wearer-trial-text") == ""
    assert "Click where you felt" not in panel
    assert "which of the two touches" not in panel
    assert page.inner_text("#wearer-message") == ""
    assert page.locator("#wearer-picture .actuator.lit").count() == 0
    assert page.locator(".alert").count() == 0, page.inner_text("#alerts")


def _stored(url: str, name: str) -> tuple[dict[str, float], dict[str, Any]]:
    answer = httpx.get(f"{url}/wearers/{name}", timeout=5.0)
    assert answer.status_code == 200, answer.text
    offsets = answer.json()["offsets_db"]["sine_100hz"]
    run = httpx.get(f"{url}/wearers/{name}/run", timeout=5.0).json()
    return {k: float(v) for k, v in offsets.items()}, run


def _ceiling_db(url: str, wearer: Wearer) -> float:
    """The highest level the test interval may take, dB re the reference interval: the
    device's max_level_db less the level the reference was played at."""
    max_db = float(httpx.get(f"{url}/device", timeout=5.0).json()["max_level_db"])
    reference_db = {t["level_db"] for t in wearer.touches if Wearer.actuator(t) == 0}
    assert len(reference_db) == 1, reference_db
    return max_db - reference_db.pop()


# --- the tests -----------------------------------------------------------------------------


def test_reference_stronger_throughout_ends_at_the_ceiling_with_a_stored_profile(
    browser: Any, services: Callable[[], LiveServer], console: ConsoleErrors
) -> None:
    service = services()
    wearer = Wearer(service.url)
    page = _open_page(browser, service.url, console, wearer)
    page.click("#wearer-match")
    assert "Give the wearer a name" in page.inner_text("#wearer-message")
    _start(page, "weak-arm")
    assert page.inner_text("#wearer-message") == "", "the warning goes once a name is given"
    trials = _answer(page, wearer, reference_stronger)
    _wait_done(page)
    offsets, run = _stored(service.url, "weak-arm")
    ceiling_db = _ceiling_db(service.url, wearer)
    print(f"reference stronger throughout: {trials} trials, ceiling {ceiling_db:g} dB")
    assert offsets.pop("1") == 0.0
    assert offsets == {str(k): pytest.approx(ceiling_db, abs=0.01) for k in range(2, 9)}
    assert len(run["trials"]) == trials
    for channel in range(2, 9):
        levels = [t["level_db"] for t in run["trials"] if t["channel"] == channel]
        assert levels == sorted(levels) and levels[-1] == pytest.approx(ceiling_db)
        assert len(levels) < 24, "a weak actuator ends at the ceiling, not after 24 trials"
    assert not any(t["test_stronger"] for t in run["trials"])
    assert "at the ceiling" in page.inner_text("#wearer-offsets")
    assert page.inner_text("#wearer-progress-text").startswith(f"Done: {trials} trials")
    _assert_finished_cleanly(page)
    page.fill("#wearer-name", "another")
    page.fill("#wearer-name", "weak-arm")
    page.press("#wearer-name", "Tab")
    page.wait_for_timeout(200)
    assert page.inner_text("#wearer-match") == "Match intensities", "a finished run is no resume"
    page.context.close()
    assert console.unexpected() == []


def test_random_answers_for_a_whole_run_store_a_profile_within_the_range(
    browser: Any, services: Callable[[], LiveServer], console: ConsoleErrors
) -> None:
    service = services()
    wearer = Wearer(service.url)
    page = _open_page(browser, service.url, console, wearer)
    _start(page, "random-07")
    trials = _answer(page, wearer, at_random(SEED))
    _wait_done(page)
    offsets, run = _stored(service.url, "random-07")
    ceiling_db = _ceiling_db(service.url, wearer)
    print(f"random answers: {trials} trials; offsets {offsets}")
    assert len(offsets) == 8 and offsets["1"] == 0.0
    assert all(-20.0 <= db <= ceiling_db for db in offsets.values()), offsets
    assert len(run["trials"]) == trials
    assert all(t["level_db"] <= ceiling_db for t in run["trials"])
    _assert_finished_cleanly(page)
    page.context.close()
    assert console.unexpected() == []


def test_a_run_stopped_mid_way_resumes_with_every_answer_kept(
    browser: Any, services: Callable[[], LiveServer], console: ConsoleErrors
) -> None:
    service = services()
    answer = at_random(SEED + 7)
    wearer = Wearer(service.url)
    page = _open_page(browser, service.url, console, wearer)
    _start(page, "stopped")
    assert _answer(page, wearer, answer, stop_after=30) == 30
    page.wait_for_function(
        "() => document.getElementById('wearer-trial').dataset.question === '31'"
    )
    page.context.close()  # the page is gone mid-run: no chance to save anything more
    saved = httpx.get(f"{service.url}/wearers/stopped/run", timeout=5.0).json()
    assert len(saved["trials"]) == 30
    assert httpx.get(f"{service.url}/wearers/stopped", timeout=5.0).status_code == 404

    page = _open_page(browser, service.url, console, wearer)
    page.fill("#wearer-name", "stopped")
    page.press("#wearer-name", "Tab")
    page.wait_for_selector("#wearer-match:has-text('Resume matching (30 answers saved)')")
    page.fill("#wearer-duration", "0.05")
    page.click("#wearer-match")
    page.wait_for_selector("#wearer-trial[data-question='1']")
    assert _trial_view(page)["progress"].startswith("Trial 31 of about ")
    assert _answer(page, wearer, answer, stop_after=10) == 10
    page.wait_for_selector("#wearer-trial[data-question='11']")
    page.click("#wearer-cancel")
    page.wait_for_selector("#wearer-trial[data-state='idle']")
    assert "Stopped after 40 answers; they are saved" in page.inner_text("#wearer-message")
    assert page.inner_text("#wearer-trial-text") == ""
    cancelled = httpx.get(f"{service.url}/wearers/stopped/run", timeout=5.0).json()
    assert cancelled["trials"][:30] == saved["trials"] and len(cancelled["trials"]) == 40

    page.click("#wearer-match")  # "Resume matching (40 answers saved)"
    page.wait_for_selector("#wearer-trial[data-question='12']")
    assert _trial_view(page)["progress"].startswith("Trial 41 of about ")
    trials = _answer(page, wearer, answer)
    _wait_done(page)
    offsets, run = _stored(service.url, "stopped")
    assert run["trials"][:40] == cancelled["trials"]
    assert len(run["trials"]) == 40 + trials
    assert len(offsets) == 8
    _assert_finished_cleanly(page)
    page.context.close()
    assert console.unexpected() == []


def _click_felt(page: Any, felt: np.ndarray) -> None:
    x, y = page.evaluate(
        """([x, y]) => {
            const svg = document.getElementById("wearer-picture");
            const p = new DOMPoint(y, x).matrixTransform(svg.getScreenCTM());
            return [p.x, p.y];
        }""",
        [float(felt[0]), float(felt[1])],
    )
    page.mouse.click(x, y)


def _check(page: Any, wearer: SimulatedWearer) -> float:
    """One localisation run; the page's mean error, checked against the wearer's own."""
    wearer.read_applied()
    first = int(page.get_attribute("#wearer-trial", "data-question") or 0) + 1
    runs = page.locator("#wearer-runs tr").count()
    page.click("#wearer-check")
    errors = []
    for number in range(first, first + len(DEVICE.triangles or ())):
        page.wait_for_selector(f"#wearer-trial[data-question='{number}']")
        assert page.get_attribute("#wearer-trial", "data-state") == "locating"
        touch = wearer.touches[-1]
        felt = wearer.felt_at(touch)
        _click_felt(page, felt)
        errors.append(float(np.linalg.norm(felt - touch["path"]["points_cm"][0])))
    page.wait_for_function(
        f"() => document.querySelectorAll('#wearer-runs tr').length === {runs + 1}"
    )
    shown = float(str(page.get_attribute("#wearer-runs tr:last-child", "data-error-cm")))
    assert shown == pytest.approx(np.mean(errors), abs=0.05)
    return shown


def test_the_procedure_recovers_the_offsets_and_applied_live_centres_the_phantom(
    browser: Any,
    services: Callable[[], LiveServer],
    console: ConsoleErrors,
    request: pytest.FixtureRequest,
) -> None:
    service = services()
    wearer = SimulatedWearer(service.url, SEED)
    page = _open_page(browser, service.url, console, wearer)
    _start(page, "simulated-07")
    page.wait_for_selector("#wearer-trial[data-question='1']")
    before = len(wearer.touches)
    page.click("#wearer-replay")
    wait_until(page, lambda: len(wearer.touches) == before + 2)
    assert wearer.touches[before:] == wearer.touches[before - 2 : before], "replay: the same"
    trials = _answer(page, wearer, wearer.answer)
    _wait_done(page)
    offsets, _ = _stored(service.url, "simulated-07")
    recovered = np.array([offsets[str(k)] for k in range(1, 9)])
    drawn = SENSITIVITY_DB[0] - SENSITIVITY_DB  # what makes each felt as actuator 1
    ceiling_db = _ceiling_db(service.url, wearer)
    minutes = trials * TRIAL_S / 60
    print(f"matching: {trials} trials, {minutes:.1f} min of the wearer's time")
    print(f"drawn offsets {np.round(drawn, 2)}, recovered {np.round(recovered, 2)}")
    others = np.arange(8) != WEAK
    assert np.max(np.abs(recovered - drawn)[others]) <= 1.0, (drawn, recovered)
    assert recovered[WEAK] == pytest.approx(ceiling_db), "the weak actuator: at the ceiling"
    assert minutes < 5.0, f"{trials} trials take {minutes:.1f} min"
    _assert_finished_cleanly(page)

    error_before = _check(page, wearer)
    page.click("#wearer-apply")
    page.wait_for_selector("#wearer-in-force[data-name='simulated-07']")
    error_after = _check(page, wearer)
    assert np.allclose(wearer.applied_db, recovered, atol=1e-4), "GET /wearer applies it"
    compare = page.inner_text("#wearer-compare")
    assert compare == (
        f"Localisation error: {error_before:.2f} cm without a profile, "
        f"{error_after:.2f} cm with simulated-07."
    )
    with page.expect_download() as download:
        page.click("#wearer-csv")
    csv = Path(download.value.path()).read_text().splitlines()
    screenshot(page, request.node.name)
    print(
        f"localisation error: {error_before:.2f} cm without the profile, "
        f"{error_after:.2f} cm with it"
    )
    assert error_before > 0.5, f"without the profile the phantom is felt {error_before:.2f} cm off"
    ideal = SimulatedWearer(service.url, SEED)
    ideal.applied_db = np.clip(drawn, -20.0, ceiling_db)  # exact offsets, the weak one capped
    ideal_cm = np.mean(
        [
            np.linalg.norm(ideal.felt_at(touch) - touch["path"]["points_cm"][0])
            for touch in wearer.touches[-6:]
        ]
    )
    print(f"with exact offsets (the weak actuator capped at the ceiling): {ideal_cm:.2f} cm")
    assert error_after < error_before, (error_before, error_after)
    assert error_after <= ideal_cm + 0.2, (error_after, ideal_cm)
    assert csv[0] == "run,wearer,intended_x_cm,intended_y_cm,felt_x_cm,felt_y_cm,error_cm"
    wearers = [line.split(",")[1] for line in csv[1:]]
    assert wearers == ["none"] * 6 + ["simulated-07"] * 6
    assert "Click where you felt" not in page.inner_text(".wearer-panel")
    page.click("#wearer-off")
    page.wait_for_selector("#wearer-in-force[data-name='']")
    assert httpx.get(f"{service.url}/wearer", timeout=5.0).json()["name"] is None
    page.context.close()
    assert console.unexpected() == []
