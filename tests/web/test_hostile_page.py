"""A page from another local origin tries to drive the armband in a real Chromium.

Two tiny HTTP servers on other loopback ports serve the same page: one origin is unknown
to the service (hostile), the other is listed in ``PHANTOMTOUCH_CORS_ORIGINS``
(friendly). The page tries what any page can: ``fetch`` with ``mode: "no-cors"`` and a
text, form or untyped JSON body to ``POST /touch`` and ``POST /stop``, a CORS ``fetch``
with a JSON body, and a WebSocket with ``hello`` and ``down``. From the hostile origin
nothing plays (the engine's voice and contact counts, sampled all along, stay 0, and no
touch is answered 202) while the service counts each refused request; from the friendly
origin the JSON touch and the WebSocket contact do play, which shows the sampling sees
what it looks for.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.live_server import HOST, LiveServer
from tests.support.metrics import sample, scrape
from tests.support.service import LONG
from tests.web.conftest import unavailable
from tests.web.support import screenshot

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>a page of another origin</title></head>
<body><pre id="log"></pre><script>
const service = "SERVICE";
const body = JSON.stringify(BODY);
const results = {};
function note(key, value) {
  results[key] = value;
  document.getElementById("log").textContent = JSON.stringify(results, null, 1);
}
async function attempt(key, path, init) {
  try {
    const answer = await fetch(service + path, init);
    note(key, answer.type === "opaque" ? "opaque" : answer.status);
  } catch (error) {
    note(key, "network error");
  }
}
function socket() {
  return new Promise((resolve) => {
    const messages = [];
    const ws = new WebSocket(service.replace("http", "ws") + "/ws");
    ws.onopen = () => {
      ws.send(JSON.stringify({type: "hello", client: "page"}));
      ws.send(JSON.stringify({type: "down", contact: "c", x_cm: 1.9, y_cm: 7.2, id: 1}));
    };
    ws.onmessage = (event) => {
      messages.push(JSON.parse(event.data).type);
      if (messages.length === 2) resolve({opened: true, messages, ws});
    };
    ws.onclose = () => resolve({opened: false, messages, ws});
  });
}
async function run() {
  await attempt("text", "/touch", {method: "POST", mode: "no-cors", body});
  await attempt("form", "/touch", {
    method: "POST", mode: "no-cors", body: new URLSearchParams({json: body})});
  await attempt("untyped", "/touch", {method: "POST", mode: "no-cors", body: new Blob([body])});
  await attempt("stop", "/stop", {method: "POST", mode: "no-cors"});
  await attempt("json", "/touch", {
    method: "POST", headers: {"Content-Type": "application/json"}, body});
  const ws = await socket();
  note("socket", {opened: ws.opened, messages: ws.messages});
  window.heldSocket = ws.ws;
  document.body.dataset.done = "true";
}
run();
</script></body></html>
"""


class PageServer:
    """A tiny HTTP server on a free loopback port that serves one page at ``/``."""

    def __init__(self) -> None:
        self.html = b""
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(outer.html)))
                self.end_headers()
                self.wfile.write(outer.html)

            def log_message(self, *args: Any) -> None:
                pass

        self.httpd = ThreadingHTTPServer((HOST, 0), Handler)
        self.port = int(self.httpd.server_address[1])
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    @property
    def origin(self) -> str:
        return f"http://{HOST}:{self.port}"

    def __enter__(self) -> PageServer:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture(scope="module")
def pages() -> Iterator[tuple[PageServer, PageServer]]:
    with PageServer() as hostile, PageServer() as friendly:
        yield hostile, friendly


@pytest.fixture(scope="module")
def service(
    tmp_path_factory: pytest.TempPathFactory, pages: tuple[PageServer, PageServer]
) -> Iterator[LiveServer]:
    _, friendly = pages
    db: Path = tmp_path_factory.mktemp("hostile") / "patterns.db"
    env = {"PHANTOMTOUCH_CORS_ORIGINS": json.dumps([friendly.origin])}
    live = LiveServer(db, env=env)
    try:
        live.start()
    except RuntimeError as exc:
        unavailable(f"the service did not start: {exc}")
    body = {**LONG, "start_in_ms": 0}
    html = PAGE.replace("SERVICE", live.url).replace("BODY", json.dumps(body)).encode()
    for page_server in pages:
        page_server.html = html
    try:
        yield live
    finally:
        live.stop()


class Sampler:
    """Reads the engine's voice and contact counts from /metrics every 20 ms."""

    def __init__(self, live: LiveServer) -> None:
        self.live = live
        self.voices: list[float] = []
        self.contacts: list[float] = []
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self.done.wait(0.02):
            text = httpx.get(f"{self.live.url}/metrics").text
            self.voices.append(sample(text, "phantomtouch_active_voices"))
            self.contacts.append(sample(text, "phantomtouch_active_contacts"))

    def __enter__(self) -> Sampler:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        time.sleep(0.2)
        self.done.set()
        self.thread.join()


def visit(browser: Any, page_server: PageServer, live: LiveServer, name: str) -> dict[str, Any]:
    """Open the page, let it run, keep it open while the counts are read; its results."""
    context = browser.new_context()
    page = context.new_page()
    try:
        with Sampler(live) as sampler:
            page.goto(f"{page_server.origin}/")
            page.wait_for_selector("body[data-done=true]", timeout=15_000)
            results: dict[str, Any] = page.evaluate("results")
            screenshot(page, name)
        results["voices"] = sampler.voices
        results["contacts"] = sampler.contacts
    finally:
        context.close()
        httpx.post(f"{live.url}/stop", timeout=5.0)
    return results


def refused(live: LiveServer, check: str, transport: str) -> float:
    return scrape(live.url, "phantomtouch_refused_requests_total", check=check, transport=transport)


def accepted_touches(live: LiveServer) -> float:
    return scrape(
        live.url, "phantomtouch_http_requests_total", method="POST", route="/touch", status="202"
    )


def test_a_page_of_another_origin_plays_nothing(
    browser: Any, service: LiveServer, pages: tuple[PageServer, PageServer]
) -> None:
    hostile, _ = pages
    origin_http_before = refused(service, "origin", "http")
    origin_ws_before = refused(service, "origin", "websocket")
    touches_before = accepted_touches(service)
    results = visit(browser, hostile, service, "hostile_page")
    assert results["voices"] and max(results["voices"]) == 0, results
    assert max(results["contacts"]) == 0, results
    assert accepted_touches(service) == touches_before
    assert results["json"] == "network error", "the preflight is refused"
    assert results["socket"] == {"opened": False, "messages": []}
    # Four no-cors writes reached the service and were refused for their Origin (the
    # preflight of the JSON fetch too), and the WebSocket handshake.
    assert refused(service, "origin", "http") >= origin_http_before + 5
    assert refused(service, "origin", "websocket") == origin_ws_before + 1


def test_a_configured_origin_plays(
    browser: Any, service: LiveServer, pages: tuple[PageServer, PageServer]
) -> None:
    _, friendly = pages
    touches_before = accepted_touches(service)
    results = visit(browser, friendly, service, "configured_origin_page")
    assert results["json"] == 202, results
    assert results["socket"] == {"opened": True, "messages": ["welcome", "ok"]}, results
    assert max(results["voices"]) >= 1
    assert max(results["contacts"]) >= 1
    assert accepted_touches(service) == touches_before + 1
    assert results["text"] == results["form"] == results["untyped"] == "opaque"
