"""Pages outside the API: the study link (/study/{id}/join), the participant page and dashboard placeholders."""

from __future__ import annotations

import html
from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.responses import HTMLResponse, RedirectResponse

from .. import services
from ..errors import NotAuthenticated
from .deps import ContextDep
from .schemas import error_responses

router = APIRouter(tags=["pages"], responses=error_responses(422))
ExternalId = Annotated[str | None, Query(max_length=128, pattern=r"^[A-Za-z0-9_.:\-]*$")]

PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{title}</title></head>
<body><main><h1>{title}</h1>{body}</main></body></html>"""


@router.get("/study/{study_id}/join", response_class=RedirectResponse, status_code=303,
            responses={303: {"description": "to the participant's page /p/{token}"}, **error_responses(404, 409)})
def join_link(study_id: str, ctx: ContextDep, PROLIFIC_PID: ExternalId = None, STUDY_ID: ExternalId = None,  # noqa: N803
              SESSION_ID: ExternalId = None) -> RedirectResponse:  # noqa: N803
    """The link given to participants: creates (or finds, by PROLIFIC_PID) the participant and redirects."""
    state, _created = services.join_study(ctx, study_id, prolific_pid=PROLIFIC_PID or None,
                                          external_study_id=STUDY_ID or None, external_session_id=SESSION_ID or None)
    return RedirectResponse(f"/p/{state['token']}", status_code=303)


@router.get("/p/{token}", response_class=HTMLResponse,
            responses={404: {"description": "unknown link", "content": {"text/html": {}}}})
def participant_page(token: str, ctx: ContextDep) -> HTMLResponse:
    """The participant's page (placeholder until the frontend lands: it names the API to use)."""
    try:
        state = services.participant_state(ctx, token)
    except NotAuthenticated:
        body = "<p>No participant has this link; check that it was copied completely.</p>"
        return HTMLResponse(PAGE.format(title="Link not found", body=body), status_code=404)
    body = (f"<p>Your session is at the <b>{html.escape(state['stage'])}</b> stage.</p>"
            "<p>The study page is coming soon. Scripted clients: <code>GET /api/v1/me</code> with "
            "<code>Authorization: Bearer &lt;the token in this page's address&gt;</code>.</p>")
    return HTMLResponse(PAGE.format(title="TableTeach study", body=body), headers={"Referrer-Policy": "no-referrer"})


@router.get("/dashboard", response_class=HTMLResponse)
def dashboard() -> HTMLResponse:
    """The experimenter dashboard (placeholder; the API under /api/v1/studies works now)."""
    body = "<p>The dashboard is coming soon. Meanwhile see <a href='/docs'>/docs</a> (experimenter endpoints).</p>"
    return HTMLResponse(PAGE.format(title="TableTeach dashboard", body=body))


@router.get("/healthz")
def health() -> dict[str, str]:
    """Liveness check."""
    return {"status": "ok", "version": services.app_version()}
