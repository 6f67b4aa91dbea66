"""The participant page's live links: the same-origin 3D view (viser's client page plus a websocket proxy
to the process's viser server on 127.0.0.1, one scene per browser), the robot's activity and the one-tab lease
(the change notices, as server-sent events, are in web/events.py).

This module and tableteach.sim are the only code that knows viser's ports (the robot gives the proxy a
ViewAddress). The proxy checks the participant's token and forwards viser's version subprotocol
(Sec-WebSocket-Protocol); without it viser closes the connection with 1002 "Version mismatch".
"""

from __future__ import annotations

import asyncio
import gzip
import logging
from functools import lru_cache
from typing import Any

import websockets
from fastapi import APIRouter, Request, WebSocket
from fastapi.responses import HTMLResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool
from starlette.websockets import WebSocketDisconnect

from .. import services
from ..errors import NotAuthenticated
from .conditional import NOT_MODIFIED, client_has, not_modified, tag_answer
from .deps import ContextDep, IdempotencyKey, TokenDep
from .frontend_files import FRONTEND
from .motion import playback_url
from .robots import viewer_client_html
from .schemas import ParticipantState, StepGuard, error_responses
from .streams import run_held

log = logging.getLogger(__name__)
router = APIRouter(tags=["participant page"])
TabId = Field(min_length=8, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
CLOSE_POLICY = 1008  # websocket close code: the request broke a rule (bad token, no view now)


class TabIn(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    tab_id: str = TabId
    takeover: bool = False


class TabReleaseIn(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    tab_id: str = TabId


class TabOut(BaseModel):
    held: bool = Field(description="true if this tab holds the page; false while another tab's lease is fresh")
    lease_seconds: float


class ViewOut(BaseModel):
    available: bool = Field(description="false when the robot has no 3D view or the participant is not at a task")
    url: str | None = Field(description="the viewer page to embed (same origin)")


class TopViewOut(BaseModel):
    layout: dict[str, Any] = Field(description="the tables, the robot's base and each object's footprint, start and "
                                   "slot, in metres seen from above (world frame)")
    step: dict[str, Any] | None = Field(description="the recorded step (task_index, kind, index), or null")
    replays: int = Field(description="how often the participant asked to watch it again")
    pending: bool = Field(description="true while the robot is still working the step's motion out: ask again")
    motion: dict[str, Any] | None = Field(description="bodies, times (s), poses per frame [x, y, z, yaw] and "
                                          "action_ends of the recorded motion, or null")


class ActivityOut(BaseModel):
    view: bool
    moving: bool
    caption: str
    watchers: int


def viewer_path(token: str) -> str:
    """The viewer page of a participant; viser's client connects its websocket to this path without the slash."""
    return f"/p/{token}/viewer/"


# viser 1.1 cannot hide its control panel (main_panel.minimize() still opens it on a narrow screen). It shows
# the websocket address (with the participant's token), "Save Canvas", "Dev Settings" and a scene tree whose
# eye icons hide objects, and pop-up notices cover the scene. The participant's copy of the client page
# hides all of them: the panel and the notices are viser's only Mantine Paper and Notifications roots.
PARTICIPANT_CLIENT_HEAD = b"""<style id="tableteach-participant">
.mantine-Paper-root, .mantine-Notifications-root, .mantine-Modal-root, .mantine-Popover-dropdown,
.mantine-Menu-dropdown { display: none !important; }
</style>"""


# Scripts that must run before viser's own: its frame pacing, and the player of the placement motions the server
# sends once (sim/motion_message.py).
VIEWER_SCRIPTS = (("viewer-pacing.js", "tableteach-pacing"), ("viewer-motion.js", "tableteach-motion"))


def inline_script(file: str, element_id: str) -> bytes:
    """A frontend script as an inline <script> (ValueError if its text would end the element early)."""
    code = (FRONTEND / file).read_bytes()
    if b"</" in code:
        raise ValueError(f"{file} contains '</': it would end its inline <script> early")
    return f'<script id="{element_id}">'.encode() + code + b"</script>"


@lru_cache(maxsize=1)
def viewer_scripts() -> bytes:
    """The viewer page's own scripts, inline, in the order they run."""
    return b"".join(inline_script(file, element_id) for file, element_id in VIEWER_SCRIPTS)


def participant_client_html(raw: bytes) -> bytes:
    """Viser's client page with the participant's style sheet, frame pacing and motion player first in its head
    (ValueError without a <head>)."""
    at = raw.find(b"<head>")
    if at < 0:
        raise ValueError("viser's client page has no <head>: expected the built index.html of viser 1.1")
    at += len(b"<head>")
    return raw[:at] + PARTICIPANT_CLIENT_HEAD + viewer_scripts() + raw[at:]


@lru_cache(maxsize=1)
def _client_bytes() -> tuple[bytes, bytes]:
    raw = participant_client_html(viewer_client_html())
    return raw, gzip.compress(raw, compresslevel=6)


@router.get("/p/{token}/viewer/", response_class=HTMLResponse, include_in_schema=False)
def viewer_page(token: str, request: Request, ctx: ContextDep) -> Response:
    """Viser's client page, served from this origin for a known participant."""
    try:
        services.participant_state(ctx, token)
    except NotAuthenticated:
        return HTMLResponse("<p>No participant has this link.</p>", status_code=404)
    raw, packed = _client_bytes()
    headers = {"Referrer-Policy": "no-referrer", "Cache-Control": "private, max-age=3600",
               "Content-Security-Policy": viewer_csp(request.headers.get("host", "")),
               "X-Content-Type-Options": "nosniff"}
    if "gzip" in request.headers.get("accept-encoding", ""):
        return Response(packed, media_type="text/html; charset=utf-8", headers={**headers, "Content-Encoding": "gzip"})
    return Response(raw, media_type="text/html; charset=utf-8", headers=headers)


def viewer_csp(host: str) -> str:
    """The viewer page's Content-Security-Policy: framed only by this origin, talking only to it.

    viser's client unpacks itself from an inline script and compiles WebAssembly, hence its script-src."""
    sockets = f" ws://{host} wss://{host}" if host and all(c.isalnum() or c in ".-:[]" for c in host) else ""
    return ("default-src 'self'; script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval' blob: data:; "
            "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
            f"connect-src 'self' data: blob:{sockets}; worker-src 'self' blob: data:; object-src 'none'; "
            "base-uri 'none'; form-action 'none'; frame-ancestors 'self'")


def same_origin(origin: str | None, host: str | None, public_url: str | None = None) -> bool:
    """Whether a websocket's Origin header names this server (by its Host header or its public URL).

    Browsers always send Origin; a client without one (not a browser) is let through, a foreign one is not."""
    if origin is None:
        return True
    from urllib.parse import urlsplit

    netloc = urlsplit(origin).netloc.lower()
    if not netloc:
        return False  # "null" (sandboxed frames, file://) or garbage
    allowed = {(host or "").lower()}
    if public_url:
        allowed.add(urlsplit(public_url).netloc.lower())
    return netloc in allowed


@router.websocket("/p/{token}/viewer")
async def viewer_socket(websocket: WebSocket, token: str) -> None:
    """Proxy the browser's websocket to the participant's viser server (started on first use)."""
    ctx = websocket.app.state.context
    if not same_origin(websocket.headers.get("origin"), websocket.headers.get("host"), ctx.settings.public_url):
        log.warning("viewer websocket refused: Origin %r is not this server", websocket.headers.get("origin"))
        await websocket.close(code=CLOSE_POLICY, reason="this view can be opened only from the study's own page")
        return
    try:
        address = await run_in_threadpool(services.open_viewer, ctx, token)
    except NotAuthenticated:
        await websocket.close(code=CLOSE_POLICY, reason="unknown participant token")
        return
    if address is None:
        await websocket.close(code=CLOSE_POLICY, reason="no 3D view at this stage of the study")
        return
    offered = list(websocket.scope.get("subprotocols") or [])
    try:
        upstream = await websockets.connect(f"ws://127.0.0.1:{address.port}{address.path}",
                                            subprotocols=offered or None,  # type: ignore[arg-type]
                                            max_size=None, compression=None, open_timeout=10)
    except (OSError, websockets.WebSocketException, asyncio.TimeoutError) as exc:
        log.warning("viewer of participant page could not reach viser on port %s: %s", address.port, exc)
        await websocket.close(code=1011, reason="the 3D view is not available; reload the page")
        return
    async with upstream:
        await websocket.accept(subprotocol=upstream.subprotocol)
        # At most a few views per participant (a newer one ends the oldest) and a cap for the process.
        if not await run_held(websocket.app.state.viewer_slots, token, _pump(websocket, upstream)):
            await websocket.close(code=1013, reason="too many 3D views are open on this server; reload in a minute")


async def _pump(browser: WebSocket, upstream: Any) -> None:
    """Copy messages both ways until either side closes, then close the other."""

    async def down() -> None:
        async for message in upstream:
            if isinstance(message, bytes):
                await browser.send_bytes(message)
            else:
                await browser.send_text(message)

    async def up() -> None:
        while True:
            message = await browser.receive()
            if message["type"] == "websocket.disconnect":
                return
            data = message.get("bytes")
            await upstream.send(data if data is not None else message.get("text", ""))

    tasks = [asyncio.create_task(down()), asyncio.create_task(up())]
    try:
        done, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in pending:
            task.cancel()
        for task in done:
            exc = task.exception()
            if exc is not None and not isinstance(exc, (WebSocketDisconnect, websockets.ConnectionClosed)):
                log.warning("viewer proxy stopped: %r", exc)
    finally:
        for task in tasks:
            task.cancel()
        await upstream.close()
        try:
            await browser.close()
        except (RuntimeError, WebSocketDisconnect):
            pass  # the browser has gone already


@router.post("/api/v1/me/view", response_model=ViewOut, responses=error_responses(401))
def open_view(ctx: ContextDep, token: TokenDep) -> dict:
    """The participant's 3D view for the current step; the page embeds `url` when available (a live view starts
    when the viewer page connects its websocket, not here)."""
    recorded = services.current_motion(ctx, token)  # a robot execution: the browser plays its recording
    if recorded is not None:
        return {"available": True, "url": playback_url(token, recorded.recording, recorded.replays)}
    available = services.prepare_viewer(ctx, token)
    return {"available": available, "url": viewer_path(token) if available else None}


@router.get("/api/v1/me/top-view", response_model=TopViewOut, responses=error_responses(401))
async def top_view(ctx: ContextDep, token: TokenDep) -> dict:
    """The page's 2D view: the tables from above and the current step's recorded motion (objects and arm, thinned
    to 15 frames a second), the same recording the 3D view plays. Reads only."""
    return await run_in_threadpool(services.flat_view, ctx, token)


@router.post("/api/v1/me/execution/replay", response_model=ParticipantState,
             responses=error_responses(400, 401, 409, 422))
async def replay(ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None, body: StepGuard | None = None) -> dict:
    """Show the robot's finished execution again in the 3D view (recorded motion); logged as replay_watched."""
    expect = services.Expect() if body is None else services.Expect(body.task_index, body.step_kind, body.step_index)
    return await run_in_threadpool(services.replay_execution, ctx, token, expect=expect, key=key)


@router.get("/api/v1/me/robot", response_model=ActivityOut, responses={**error_responses(401), **NOT_MODIFIED})
async def robot_activity(request: Request, response: Response, ctx: ContextDep, token: TokenDep) -> Any:
    """Whether the robot is moving, what it is doing, and how many 3D views are connected (with an ETag)."""
    activity = await run_in_threadpool(services.robot_activity, ctx, token)
    tag = services.activity_tag(activity)
    if client_has(request, tag):
        return not_modified(tag)
    tag_answer(response, tag)
    return activity


@router.post("/api/v1/me/tab", response_model=TabOut, responses=error_responses(400, 401, 422))
async def claim_tab(body: TabIn, ctx: ContextDep, token: TokenDep) -> dict:
    """Hold or renew this tab's lease on the page (renew every few seconds); takeover moves it here."""
    return await run_in_threadpool(services.claim_tab, ctx, token, body.tab_id, takeover=body.takeover)


@router.post("/api/v1/me/tab/release", status_code=204, responses=error_responses(400, 401, 422))
def release_tab(body: TabReleaseIn, ctx: ContextDep, token: TokenDep) -> Response:
    """The tab is reloading or closing: free the lease at once."""
    services.release_tab(ctx, token, body.tab_id)
    return Response(status_code=204)
