"""The experimenter dashboard page (/dashboard), its own static files (no build step, nothing from a CDN) and the
server's front page (/), which points participants and experimenters to the right place."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import FileResponse, HTMLResponse

from .frontend_files import FRONTEND, allowed_file

ASSETS = {
    "dashboard.js": "text/javascript",
    "dashboard-api.js": "text/javascript",
    "dashboard-study-form.js": "text/javascript",
    "dashboard-ui.js": "text/javascript",
    "dashboard-prolific.js": "text/javascript",
    "dashboard-accounts.js": "text/javascript",
    "dashboard-what-if.js": "text/javascript",
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

router = APIRouter(tags=["pages"], include_in_schema=False)  # HTML pages: not part of the API


@router.get("/dashboard", response_class=FileResponse, responses={200: {"content": {"text/html": {}}}})
def dashboard_page() -> FileResponse:
    """The experimenter dashboard (log in with the experimenter token)."""
    return FileResponse(FRONTEND / "dashboard.html", media_type="text/html; charset=utf-8", headers=HEADERS)


@router.get("/dashboard/assets/{name}", response_class=FileResponse, responses={404: {"description": "no such file"}})
def dashboard_asset(name: str) -> FileResponse:
    """One of the dashboard's scripts or its stylesheet."""
    return allowed_file(name, ASSETS, what="dashboard asset", headers=HEADERS)


HOME = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>TableTeach study server</title><link rel="stylesheet" href="/dashboard/assets/dashboard.css"></head>
<body><main class="home">
<h1>TableTeach study server</h1>
<p><strong>Taking part in a study?</strong> Please open the link you were given (for example on Prolific);
this page has nothing to do.</p>
<p><strong>Running a study?</strong></p>
<ul>
<li><a href="/dashboard">Experimenter dashboard</a>: create, pilot, open and monitor studies, download the data.</li>
<li>{api_docs} (the REST API the dashboard and scripted teachers use).</li>
<li><a href="/healthz">Health check</a>.</li>
</ul>
</main></body></html>"""


@router.get("/", response_class=HTMLResponse)
def home(request: Request) -> HTMLResponse:
    """The front page: where participants and experimenters should go (the API docs page exists in dev mode only)."""
    dev = request.app.state.settings.dev_mode
    api_docs = '<a href="/docs">API documentation</a>' if dev else '<a href="/openapi.json">API schema</a>'
    return HTMLResponse(HOME.replace("{api_docs}", api_docs), headers=HEADERS)
