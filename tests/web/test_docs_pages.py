"""``/docs`` and ``/redoc`` in chromium with the network off: every asset from the service.

Each page is opened in a context where every request to another host than the service is
aborted (as on a lab PC without internet) and recorded; the page must render the API
(its operations, its models) from the service's own files and ask no other host.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.web.support import VIEWPORT, screenshot

RENDER_TIMEOUT_MS = 20_000


@pytest.fixture
def offline_page(browser: Any, server: str) -> Iterator[tuple[Any, list[str]]]:
    """A page that reaches the service only; the URLs it tried elsewhere."""
    context = browser.new_context(viewport=VIEWPORT)
    foreign: list[str] = []

    def only_the_service(route: Any) -> None:
        url = route.request.url
        if url.startswith((f"{server}/", "data:", "blob:")):
            route.continue_()
        else:
            foreign.append(url)
            route.abort("internetdisconnected")

    context.route("**/*", only_the_service)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        yield page, foreign
    finally:
        context.close()
    assert errors == []


def test_swagger_ui_works_offline(offline_page: tuple[Any, list[str]], server: str) -> None:
    page, foreign = offline_page
    answers: list[tuple[str, int]] = []
    page.on("response", lambda response: answers.append((response.url, response.status)))
    page.goto(f"{server}/docs")
    page.wait_for_selector(".opblock-summary-path", timeout=RENDER_TIMEOUT_MS)
    paths = page.locator(".opblock-summary-path").all_inner_texts()
    assert "/touch" in paths
    assert "/patterns/{name}/play" in paths
    page.get_by_text("NamedTouch", exact=True).first.wait_for(timeout=RENDER_TIMEOUT_MS)
    assert (f"{server}/static/docs/swagger-ui-bundle.js", 200) in answers
    assert (f"{server}/openapi.json", 200) in answers
    assert foreign == []
    screenshot(page, "docs_swagger_offline")


def test_redoc_works_offline(offline_page: tuple[Any, list[str]], server: str) -> None:
    page, foreign = offline_page
    page.goto(f"{server}/redoc")
    page.locator("h2", has_text="Play a touch").first.wait_for(timeout=RENDER_TIMEOUT_MS)
    assert page.locator("h1").first.inner_text().startswith("phantomtouch")
    assert page.locator("h2", has_text="Play a stored pattern").count() == 1
    assert foreign == []
    screenshot(page, "docs_redoc_offline")
