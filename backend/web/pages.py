"""Pages outside the API: the study link (/study/{id}/join), the participant page and its static files."""

from __future__ import annotations

from html import escape
from typing import Annotated, Literal
from urllib.parse import quote

from fastapi import APIRouter, Query, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from pydantic import BaseModel, Field

from .. import services
from ..services import goal_pictures
from ..errors import NotAuthenticated
from .browser import browser_secret, remember_browser
from .deps import ContextDep, JoinAllowed
from .frontend_files import FRONTEND, allowed_file
from .schemas import error_responses

router = APIRouter(tags=["operations"], responses=error_responses(422))  # its pages stay out of the schema
ExternalId = Annotated[str | None, Query(max_length=128, pattern=r"^[A-Za-z0-9_.:\-]*$")]

ASSETS = {
    "participant.js": "text/javascript; charset=utf-8",
    "participant-views.js": "text/javascript; charset=utf-8",
    "participant-study-ops.js": "text/javascript; charset=utf-8",
    "participant-top-view.js": "text/javascript; charset=utf-8",
    "participant-view-mode.js": "text/javascript; charset=utf-8",
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
PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1"><meta name="referrer" content="no-referrer">
<title>{title}</title><link rel="stylesheet" href="/participant/assets/style.css"></head>
<body><header class="topbar"><span class="brand">Teach a robot to set the table</span></header>
<main><div class="screen"><section class="card narrow" id="message"><h1>{title}</h1>{body}</section></div></main>
</body></html>"""
CONTACT = ("<p>If you came from a recruitment platform such as Prolific, go back there and contact the researchers "
           "through its messages; they can help you.</p>")
# What a participant reads instead of an error answer on the pages they can reach: (title, what to do).
PAGE_ERRORS = {
    400: ("This link did not work", "<p>The link could not be used as it is. Please open it again exactly as "
          "you were given it.</p>"),
    401: ("Link not found", "<p>No participant has this link. Check that the whole link was copied, or open "
          "the study again from the platform that sent you.</p>"),
    404: ("Link not found", "<p>This link does not lead to a study on this server. Check that the whole link "
          "was copied, or open the study again from the platform that sent you.</p>"),
    409: ("This study is not open", "<p>The study is not taking participants at the moment: it may not have "
          "started yet, or it may be full or finished. Nothing about you has been recorded.</p>"),
    422: ("This link is incomplete", "<p>Part of the link is missing or damaged. Please open it again exactly "
          "as you were given it.</p>"),
    429: ("Please wait a minute", "<p>Many people have just opened this study from your network. Please wait a "
          "minute, then open the link again. Nothing about you has been recorded.</p>"),
}
STUDY_FULL = ("This study is full", "<p>All places in this study are taken, so it cannot take you now. Nothing "
              "about you has been recorded.</p>")
# A 409 on the join link when the PROLIFIC_PID joined before from another browser and Prolific session.
RESUME_REFUSED = ("You have already started this study", "<p>This participant id has already started this study "
                  "in another browser. To continue, open the study link again in the browser you started in, or "
                  "from the same Prolific session.</p>")
SERVER_ERROR = ("Something went wrong on our side", "<p>The study server could not answer just now. Please "
                "wait a minute and reload the page; your progress so far is saved.</p>")
PAGE_PREFIXES = ("/study/", "/p/")


def is_page(path: str) -> bool:
    """True for addresses a participant opens in the browser (they get HTML); the API answers JSON."""
    return path.startswith(PAGE_PREFIXES)


def error_page(status: int, headers: dict[str, str] | None = None, *, resume_refused: bool = False,
               study_full: bool = False) -> HTMLResponse:
    """A plain-words HTML page for an error on a participant-facing address: what happened, what to do.

    `headers` are the error's own (e.g. Allow on a 405); `resume_refused` for a 409 that refused to resume,
    `study_full` for one whose study has no place left."""
    title, body = (RESUME_REFUSED if resume_refused else STUDY_FULL if study_full
                   else PAGE_ERRORS.get(status, SERVER_ERROR if status >= 500 else PAGE_ERRORS[400]))
    return HTMLResponse(PAGE.format(title=title, body=body + CONTACT), status_code=status,
                        headers={**(headers or {}), "Referrer-Policy": "no-referrer", "Cache-Control": "no-store"})


@router.get("/study/{study_id}/join", response_class=RedirectResponse, status_code=303, dependencies=[JoinAllowed],
            include_in_schema=False,
            responses={303: {"description": "to the participant's page /p/{token}"},
                       200: {"description": "no PROLIFIC_PID and the study does not allow anonymous participants: "
                             "a page asking for the Prolific ID", "content": {"text/html": {}}},
                       404: {"description": "no such study (an HTML page)", "content": {"text/html": {}}},
                       409: {"description": "the study is not open or full, or this PROLIFIC_PID joined before from "
                             "another browser and session (an HTML page)", "content": {"text/html": {}}},
                       429: {"description": "too many joins from this address; Retry-After (an HTML page)",
                             "content": {"text/html": {}}},
                       422: {"description": "a damaged link (an HTML page)", "content": {"text/html": {}}}})
def join_link(study_id: str, ctx: ContextDep, request: Request, PROLIFIC_PID: ExternalId = None,  # noqa: N803
              STUDY_ID: ExternalId = None, SESSION_ID: ExternalId = None) -> Response:  # noqa: N803
    """The link given to participants: creates the participant (or finds, by PROLIFIC_PID with the same
    SESSION_ID or browser, the one who joined before) and redirects to their page. Without a PROLIFIC_PID, an open
    study that does not allow anonymous participants answers with a page asking for the Prolific ID."""
    if not PROLIFIC_PID:
        study = services.get_study(ctx, study_id)
        if study["status"] == "open" and not study["allow_anonymous"]:
            return ask_prolific_id(study_id, STUDY_ID, SESSION_ID)
    secret = browser_secret(request)
    state, _created = services.join_study(ctx, study_id, prolific_pid=PROLIFIC_PID or None,
                                          external_study_id=STUDY_ID or None, external_session_id=SESSION_ID or None,
                                          browser_secret=secret)
    response = RedirectResponse(f"/p/{state['token']}", status_code=303)
    remember_browser(request, response, secret)
    return response


def ask_prolific_id(study_id: str, external_study_id: str | None, session_id: str | None) -> HTMLResponse:
    """The page that asks for the Prolific ID (the study link came without PROLIFIC_PID); it sends the same link
    with the ID filled in."""
    hidden = "".join(f'<input type="hidden" name="{name}" value="{escape(value)}">'
                     for name, value in (("STUDY_ID", external_study_id), ("SESSION_ID", session_id)) if value)
    body = (f'<p>This link did not include your Prolific ID. Please enter it to take part (it is how the '
            f'researchers pay you). You find it on your Prolific account page.</p>'
            f'<form method="get" action="/study/{quote(study_id, safe="")}/join" class="ask-id">'
            f'<label for="prolific-id">Your Prolific ID</label>'
            f'<input id="prolific-id" name="PROLIFIC_PID" required autocomplete="off" spellcheck="false" '
            rf'pattern="[A-Za-z0-9_.:\-]{{1,128}}" maxlength="128" aria-describedby="prolific-id-hint">'
            f'<p id="prolific-id-hint" class="hint">Letters and digits, as Prolific shows it.</p>{hidden}'
            f'<div class="buttons"><button class="primary" type="submit">Continue</button></div></form>')
    return HTMLResponse(PAGE.format(title="Your Prolific ID", body=body + CONTACT), headers=PAGE_HEADERS)


@router.get("/p/{token}", response_class=FileResponse, include_in_schema=False,
            responses={200: {"content": {"text/html": {}}},
                       404: {"description": "unknown link", "content": {"text/html": {}}}})
def participant_page(token: str, ctx: ContextDep) -> Response:
    """The participant's page (frontend/participant.html); it reads the token from its own address."""
    try:
        services.participant_state(ctx, token)
    except NotAuthenticated:
        return error_page(404)
    return FileResponse(FRONTEND / "participant.html", media_type="text/html; charset=utf-8", headers=PAGE_HEADERS)


@router.get("/participant/assets/{name}", response_class=FileResponse, include_in_schema=False,
            responses={404: {"description": "no such file"}})
def participant_asset(name: str) -> FileResponse:
    """A script, style sheet or picture of the participant page (only the files listed in ASSETS)."""
    return allowed_file(name, ASSETS, what="participant asset", headers={"Cache-Control": "no-cache"})


class HealthOut(BaseModel):
    status: Literal["ok"]
    version: str = Field(description="the server's version")


@router.get("/study/{study_id}/goal/{task_index}.svg", include_in_schema=False,
            responses={200: {"content": {"image/svg+xml": {}}}, 404: {"description": "no such study or task"}})
def goal_picture(study_id: str, task_index: int, ctx: ContextDep) -> Response:
    """A task's goal picture in a study with its own objects (Table B from above, drawn from its layout)."""
    svg = goal_pictures.goal_picture(ctx, study_id, task_index)
    return Response(svg, media_type="image/svg+xml", headers={"Cache-Control": "no-cache",
                                                             "Content-Security-Policy": "default-src 'none'"})


@router.get("/healthz", response_model=HealthOut, responses=error_responses(503))
def health(ctx: ContextDep) -> dict[str, str]:
    """Health check: 200 while the database answers; 503 (with Retry-After) when it is busy, missing or replaced."""
    ctx.db.health()
    return {"status": "ok", "version": services.app_version()}
