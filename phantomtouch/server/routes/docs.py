"""``/docs`` (Swagger UI) and ``/redoc``, with their scripts served by the service itself.

FastAPI's own pages load Swagger UI and ReDoc from a public CDN, so a lab PC without
internet shows a blank page. The assets come from the ``fastapi-offline`` distribution
(``swagger-ui-bundle.js``, ``swagger-ui.css``, ``redoc.standalone.js``, ``favicon.png``)
and are mounted at :data:`ASSETS_PATH`; neither page asks another host for anything
(no web fonts, no validator badge), and both are sent with a Content-Security-Policy
that keeps the browser on the service (ReDoc's sidebar asks a CDN for its logo, which
the policy refuses before any request leaves the machine).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib.resources import files
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse

ASSETS_DIR = Path(str(files("fastapi_offline") / "static"))
"""Swagger UI and ReDoc as the ``fastapi-offline`` distribution ships them."""
ASSETS_PATH = "/static/docs"
"""Where :data:`ASSETS_DIR` is mounted (open without a token, as the web page's files)."""
TITLE = "phantomtouch"
SAME_ORIGIN_ONLY = "; ".join(
    (
        "default-src 'self'",
        "script-src 'self' 'unsafe-inline'",
        "style-src 'self' 'unsafe-inline'",
        "img-src 'self' data:",
        "font-src 'self' data:",
        "worker-src 'self' blob:",
    )
)
"""The pages' Content-Security-Policy: everything from the service (inline: their set-up)."""

router = APIRouter(include_in_schema=False)


def _page(
    request: Request,
    html: Callable[..., HTMLResponse],
    name: str,
    assets: dict[str, str],
    **options: Any,
) -> HTMLResponse:
    """The page ``html`` renders on ``/openapi.json``, titled ``name``: each argument of
    ``assets`` names a file of :data:`ASSETS_PATH`; sent with :data:`SAME_ORIGIN_ONLY`."""
    root = str(request.scope.get("root_path", "")).rstrip("/")
    page = html(
        openapi_url=f"{root}/openapi.json",
        title=f"{TITLE} - {name}",
        **{argument: f"{root}{ASSETS_PATH}/{file}" for argument, file in assets.items()},
        **options,
    )
    page.headers["Content-Security-Policy"] = SAME_ORIGIN_ONLY
    return page


@router.get("/docs")
async def swagger_ui(request: Request) -> HTMLResponse:
    """Swagger UI on ``/openapi.json``."""
    assets = {
        "swagger_js_url": "swagger-ui-bundle.js",
        "swagger_css_url": "swagger-ui.css",
        "swagger_favicon_url": "favicon.png",
    }
    return _page(
        request,
        get_swagger_ui_html,
        "Swagger UI",
        assets,
        swagger_ui_parameters={"validatorUrl": None},
    )


@router.get("/redoc")
async def redoc(request: Request) -> HTMLResponse:
    """ReDoc on ``/openapi.json``."""
    assets = {"redoc_js_url": "redoc.standalone.js", "redoc_favicon_url": "favicon.png"}
    return _page(request, get_redoc_html, "ReDoc", assets, with_google_fonts=False)
