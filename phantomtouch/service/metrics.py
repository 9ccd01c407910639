"""Prometheus metrics: requests, latency and WebSocket messages, plus engine gauges.

Each app has its own registry (two apps in one process do not collide). The engine's
figures (active voices, underruns, late commands, peak level ...) are read from
``engine.status()`` when ``/metrics`` is scraped, never pushed from the audio thread.
"""

from __future__ import annotations

import collections
import functools
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
_LATENCY_BUCKETS_S = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 5.0)

_INGEST_BUCKETS_S = (
    2e-6,
    5e-6,
    1e-5,
    2e-5,
    3e-5,
    5e-5,
    7.5e-5,
    1e-4,
    2e-4,
    5e-4,
    1e-3,
    2e-3,
    5e-3,
    1e-2,
)

StatusReader = Callable[[], dict[str, Any]]

FRAME_REFUSALS: collections.Counter[str] = collections.Counter()
"""WebSocket frames refused before any session reads them, by reason (``invalid_utf8``):
counted by the server's protocol (:mod:`phantomtouch.server.wire`, on the event loop),
one count per process, which serves one app."""


CONNECTION_REFUSALS: collections.Counter[str] = collections.Counter()
"""Connections refused by the HTTP protocol before the app saw a request, by reason
(``header_timeout``, ``header_too_large``, ``budget``): counted by
:mod:`phantomtouch.server.guard` on the event loop, one count per process."""
CONNECTION_BUDGET: dict[str, int] = {}
"""The open-file limit and the connection budget the server runs with (``open_files``,
``connections``, ``stop_lane``), set once at start (:mod:`phantomtouch.server.serve`)."""


def labelled(
    family: type[CounterMetricFamily | GaugeMetricFamily],
    name: str,
    documentation: str,
    label: str,
    values: Mapping[str, float],
) -> Metric:
    """One family with a sample per value of one label (pure).

    Parameters
    ----------
    family : CounterMetricFamily or GaugeMetricFamily
    name, documentation : str
    label : str
        The label's name (``outcome``, ``reason``, ``quantile``).
    values : mapping of str to float
        The samples, by the label's value, in the order given.
    """
    metric = family(name, documentation, labels=[label])
    for key, value in values.items():
        metric.add_metric([key], value)
    return metric


class FunctionCollector(Collector):
    """A collector whose families come from one function, called at each scrape (the
    scraping thread): how the service and every input (OSC, the bHaptics listeners) show
    their counts.

    Parameters
    ----------
    families : callable () -> iterable of Metric
    """

    def __init__(self, families: Callable[[], Iterable[Metric]]) -> None:
        self.families = families

    def collect(self) -> Iterator[Metric]:
        yield from self.families()


def _connection_families() -> Iterator[Metric]:
    yield labelled(
        CounterMetricFamily,
        "phantomtouch_connections_refused",
        "Connections refused before a request reached the app, by reason (header_timeout: "
        "408, header_too_large: 431, budget: over the connection budget).",
        "reason",
        {
            reason: CONNECTION_REFUSALS[reason]
            for reason in ("budget", "header_timeout", "header_too_large")
        },
    )
    for name, value in sorted(CONNECTION_BUDGET.items()):
        yield GaugeMetricFamily(
            f"phantomtouch_connection_budget_{name}",
            "The connection budget the server started with (open_files: the open-file "
            "limit; connections: served at once; stop_lane: more for POST /stop only).",
            value=value,
        )


def _frame_families() -> Iterator[Metric]:
    yield labelled(
        CounterMetricFamily,
        "phantomtouch_ws_refused_frames",
        "WebSocket frames refused by the protocol before a session read them, by reason "
        "(invalid_utf8: a text frame that is not UTF-8, closed with 1007).",
        "reason",
        {
            reason: FRAME_REFUSALS[reason]
            for reason in ("invalid_utf8", *sorted(set(FRAME_REFUSALS) - {"invalid_utf8"}))
        },
    )


_CALLBACK_QUANTILES = (
    (
        "phantomtouch_render_load",
        "Audio callback time over the last 4096 blocks, as a fraction of the time each "
        "callback had (the sound card's period).",
        {"0.99": "render_load_p99", "1": "render_load_max"},
    ),
    (
        "phantomtouch_callback_seconds",
        "Audio callback time over the last 4096 blocks, s.",
        {"0.5": "callback_p50_s", "0.99": "callback_p99_s", "1": "callback_max_s"},
    ),
)
"""The audio callback's time by quantile: each family's name, help and the status key of
each quantile."""


class _EngineCollector(Collector):
    def __init__(self) -> None:
        self.read: StatusReader | None = None

    def collect(self) -> Iterator[Metric]:
        if self.read is None:
            return
        status = self.read()
        yield GaugeMetricFamily(
            "phantomtouch_active_voices", "Voices playing now.", value=status["active_voices"]
        )
        yield GaugeMetricFamily(
            "phantomtouch_active_contacts",
            "Live contacts held down now.",
            value=len(status["active_contacts"]),
        )
        yield CounterMetricFamily(
            "phantomtouch_underruns", "Audio blocks the sound card missed.", status["underruns"]
        )
        yield CounterMetricFamily(
            "phantomtouch_late_commands",
            "Commands that reached the audio thread after their start time.",
            status["late_commands"],
        )
        yield CounterMetricFamily(
            "phantomtouch_inline_renders",
            "Times the audio callback rendered a pattern voice's samples itself because the "
            "render-ahead thread had not kept its ring filled.",
            status["inline_renders"],
        )
        yield labelled(
            CounterMetricFamily,
            "phantomtouch_silenced_voices",
            "Voices silenced alone while the others played on, by reason (non_finite: a "
            "sample NaN or Inf; over_budget: past the render budget block after block).",
            "reason",
            {"non_finite": status["nonfinite_voices"], "over_budget": status["overrun_voices"]},
        )
        yield CounterMetricFamily(
            "phantomtouch_muted_blocks",
            "Output blocks the output stage replaced by silence for a NaN or Inf in the mix "
            "(every voice silent for that block; a voice's own NaN is silenced alone first).",
            status["muted_blocks"],
        )
        yield CounterMetricFamily(
            "phantomtouch_dc_blocked_blocks",
            "Blocks the DC blocker changed (content far below the carriers' band).",
            status["dc_blocked_blocks"],
        )
        yield CounterMetricFamily(
            "phantomtouch_limited_blocks",
            "Blocks the safety limiter had to scale down.",
            status["limited_blocks"],
        )
        yield GaugeMetricFamily(
            "phantomtouch_peak_level",
            "Largest absolute output sample since the engine started (full scale 1).",
            status["peak"],
        )
        yield GaugeMetricFamily(
            "phantomtouch_queue_depth",
            "Commands waiting for the audio thread.",
            status["queue_depth"],
        )
        for name, documentation, keys in _CALLBACK_QUANTILES:
            quantiles = {quantile: status[key] for quantile, key in keys.items()}
            yield labelled(GaugeMetricFamily, name, documentation, "quantile", quantiles)
        yield GaugeMetricFamily(
            "phantomtouch_period_frames",
            "Frames of each audio callback: the sound card's period.",
            status["period_frames"],
        )
        yield GaugeMetricFamily(
            "phantomtouch_voice_capacity",
            "Pattern voices admitted at once: the render budget over one voice's cost.",
            status["voice_capacity"],
        )
        yield GaugeMetricFamily(
            "phantomtouch_voice_cost",
            "Measured render time of one pattern voice, a fraction of a block's playing time.",
            status["voice_cost"],
        )
        yield GaugeMetricFamily(
            "phantomtouch_render_budget",
            "Share of a block's playing time pattern voices may take.",
            status["render_budget"],
        )
        yield GaugeMetricFamily(
            "phantomtouch_engine_running",
            "1 while audio flows; 0 while the engine process is stalled, gone or restarting.",
            1.0 if status["state"] == "running" else 0.0,
        )
        yield CounterMetricFamily(
            "phantomtouch_engine_restarts",
            "Times the engine process was restarted after it died or stalled.",
            status["restarts"],
        )
        yield labelled(
            GaugeMetricFamily,
            "phantomtouch_channel_peak_level",
            "Largest absolute sample per output channel in the last block (full scale 1).",
            "channel",
            {str(k): level for k, level in enumerate(status["levels"], start=1)},
        )


class Metrics:
    """The registry of one app and the instruments the service updates."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        counter = functools.partial(Counter, registry=self.registry)
        histogram = functools.partial(Histogram, registry=self.registry)
        self.requests = counter(
            "phantomtouch_http_requests",
            "HTTP requests by route template, method and status (499: the client left "
            "before its request arrived whole).",
            ["route", "method", "status"],
        )
        self.latency = histogram(
            "phantomtouch_http_request_duration_seconds",
            "Time from request to the end of the response, by route template.",
            ["route"],
            buckets=_LATENCY_BUCKETS_S,
        )
        self.ws_messages = counter(
            "phantomtouch_ws_messages",
            "WebSocket messages by direction (in/out) and type.",
            ["direction", "type"],
        )
        self.ws_ingest = histogram(
            "phantomtouch_ws_move_ingest_seconds",
            "From a move frame's receipt in the session to engine.contact_move returning.",
            buckets=_INGEST_BUCKETS_S,
        )
        self.ws_watchdog_releases = counter(
            "phantomtouch_ws_watchdog_releases",
            "Times a silent connection's contacts were released by the watchdog.",
        )
        self.ws_dropped = counter(
            "phantomtouch_ws_dropped_messages",
            "WebSocket messages dropped unanswered: over the connection's message rate.",
        )
        self.ws_flood_closes = counter(
            "phantomtouch_ws_flood_closes",
            "WebSocket connections closed (1008) for staying over their message rate.",
        )
        self.ws_connections = counter(
            "phantomtouch_ws_connections", "WebSocket connections accepted."
        )
        self.ws_open = Gauge(
            "phantomtouch_ws_open_connections",
            "WebSocket connections open now.",
            registry=self.registry,
        )
        self.ws_refused = counter(
            "phantomtouch_ws_refused_connections",
            "WebSocket connections closed 1013 by the connection slots (cap: yielded, a "
            "connection that gave its slot to a newcomer; full, one refused a slot).",
            ["cap"],
        )
        self.refused_requests = counter(
            "phantomtouch_refused_requests",
            "Requests and WebSocket handshakes refused for their Host, Origin or content "
            "type (check: host, origin, content_type; transport: http, websocket).",
            ["check", "transport"],
        )
        self._engine = _EngineCollector()
        self.registry.register(self._engine)
        self.registry.register(FunctionCollector(_frame_families))
        self.registry.register(FunctionCollector(_connection_families))

    def watch_engine(self, read: StatusReader | None) -> None:
        """Read the engine's figures with ``read`` at scrape time (None: stop)."""
        self._engine.read = read

    def exposition(self) -> bytes:
        return generate_latest(self.registry)


class MetricsMiddleware:
    """Count every HTTP request by route template and status, and time it."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            self.metrics.requests.labels(template, scope["method"], str(status)).inc()
            self.metrics.latency.labels(template).observe(time.perf_counter() - started)
