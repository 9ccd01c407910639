"""The web page: ``GET /`` serves ``static/index.html``; ``/static`` the files beside it."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

from phantomtouch.service.errors import NotFoundError

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"

router = APIRouter(include_in_schema=False)


@router.get("/")
async def index() -> FileResponse:
    page = STATIC_DIR / "index.html"
    if not page.is_file():
        raise NotFoundError(
            "the web page is not installed (phantomtouch/server/static/index.html)", field="path"
        )
    return FileResponse(page, media_type="text/html")
