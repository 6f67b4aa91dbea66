"""The experimenter dashboard page (/dashboard) and its own static files (no build step, nothing from a CDN)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse

from .frontend_files import FRONTEND, allowed_file

ASSETS = {
    "dashboard.js": "text/javascript",
    "dashboard-api.js": "text/javascript",
    "charts.js": "text/javascript",
    "dom.js": "text/javascript",
    "dashboard.css": "text/css",
}
HEADERS = {
    "Cache-Control": "no-cache",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    # The experimenter token lives in sessionStorage: allow no script or connection beyond this origin.
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; "
                               "script-src 'self'; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'",
}

router = APIRouter(tags=["pages"])


@router.get("/dashboard", response_class=FileResponse, responses={200: {"content": {"text/html": {}}}})
def dashboard_page() -> FileResponse:
    """The experimenter dashboard (log in with the experimenter token)."""
    return FileResponse(FRONTEND / "dashboard.html", media_type="text/html; charset=utf-8", headers=HEADERS)


@router.get("/dashboard/assets/{name}", response_class=FileResponse, responses={404: {"description": "no such file"}})
def dashboard_asset(name: str) -> FileResponse:
    """One of the dashboard's scripts or its stylesheet."""
    return allowed_file(name, ASSETS, what="dashboard asset", headers=HEADERS)
