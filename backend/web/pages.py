"""Pages outside the API: the study link (/study/{id}/join), the participant page and its static files."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response

from .. import services
from ..errors import NotAuthenticated
from .browser import browser_secret, remember_browser
from .deps import ContextDep
from .frontend_files import FRONTEND, allowed_file
from .schemas import error_responses

router = APIRouter(tags=["pages"], responses=error_responses(422))
ExternalId = Annotated[str | None, Query(max_length=128, pattern=r"^[A-Za-z0-9_.:\-]*$")]

ASSETS = {
    "participant.js": "text/javascript; charset=utf-8",
    "participant-views.js": "text/javascript; charset=utf-8",
    "participant-study-ops.js": "text/javascript; charset=utf-8",
    "participant-study-ops.css": "text/css; charset=utf-8",
    "dom.js": "text/javascript; charset=utf-8",
    "api.js": "text/javascript; charset=utf-8",
    "style.css": "text/css; charset=utf-8",
    "goal-task1.png": "image/png",
    "goal-task2.png": "image/png",
}
# The page carries the participant's token in its address: never leak it in a Referer header.
PAGE_HEADERS = {
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; frame-src 'self'; object-src 'none'; "
                               "base-uri 'none'; frame-ancestors 'none'",
}
PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{title}</title></head>
<body><main><h1>{title}</h1>{body}</main></body></html>"""


@router.get("/study/{study_id}/join", response_class=RedirectResponse, status_code=303,
            responses={303: {"description": "to the participant's page /p/{token}"}, **error_responses(404, 409)})
def join_link(study_id: str, ctx: ContextDep, request: Request, PROLIFIC_PID: ExternalId = None,  # noqa: N803
              STUDY_ID: ExternalId = None, SESSION_ID: ExternalId = None) -> RedirectResponse:  # noqa: N803
    """The link given to participants: creates the participant (or finds, by PROLIFIC_PID with the same
    SESSION_ID or browser, the one who joined before) and redirects to their page."""
    secret = browser_secret(request)
    state, _created = services.join_study(ctx, study_id, prolific_pid=PROLIFIC_PID or None,
                                          external_study_id=STUDY_ID or None, external_session_id=SESSION_ID or None,
                                          browser_secret=secret)
    response = RedirectResponse(f"/p/{state['token']}", status_code=303)
    remember_browser(request, response, secret)
    return response


@router.get("/p/{token}", response_class=FileResponse,
            responses={200: {"content": {"text/html": {}}},
                       404: {"description": "unknown link", "content": {"text/html": {}}}})
def participant_page(token: str, ctx: ContextDep) -> Response:
    """The participant's page (frontend/participant.html); it reads the token from its own address."""
    try:
        services.participant_state(ctx, token)
    except NotAuthenticated:
        body = "<p>No participant has this link; check that it was copied completely.</p>"
        return HTMLResponse(PAGE.format(title="Link not found", body=body), status_code=404)
    return FileResponse(FRONTEND / "participant.html", media_type="text/html; charset=utf-8", headers=PAGE_HEADERS)


@router.get("/participant/assets/{name}", response_class=FileResponse,
            responses={404: {"description": "no such file"}})
def participant_asset(name: str) -> FileResponse:
    """A script, style sheet or picture of the participant page (only the files listed in ASSETS)."""
    return allowed_file(name, ASSETS, what="participant asset", headers={"Cache-Control": "no-cache"})


@router.get("/healthz", responses=error_responses(503))
def health(ctx: ContextDep) -> dict[str, str]:
    """Health check: 200 while the database answers; 503 (with Retry-After) when it is busy, missing or replaced."""
    ctx.db.health()
    return {"status": "ok", "version": services.app_version()}
