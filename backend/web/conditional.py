"""Conditional GETs: answer 304 Not Modified when the client's If-None-Match names the current entity tag.

The page polls its state and its robot's activity every few seconds; nearly every poll finds nothing new. The
PollsNotModified middleware answers those before routing (one small query, no dependency injection, no response
model); any other request, and any poll whose tag has changed, goes through the app as usual."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import Request, Response
from starlette.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Receive, Scope, Send

from .. import services
from ..errors import TableTeachError

# The participant's answers are private to them and must be checked with the server before reuse.
POLL_HEADERS = {"Cache-Control": "private, no-cache"}
NOT_MODIFIED: dict[int | str, dict[str, Any]] = {
    304: {"description": "nothing changed since the answer whose ETag was sent in If-None-Match"}}


def names_tag(header: str | None, tag: str | None) -> bool:
    """Whether an If-None-Match value names `tag` (weak comparison, as RFC 9110 asks for GET)."""
    if not header or tag is None:
        return False
    wanted = tag.removeprefix("W/")
    return any(t.strip() == "*" or t.strip().removeprefix("W/") == wanted for t in header.split(","))


def client_has(request: Request, tag: str | None) -> bool:
    """Whether the request's If-None-Match names `tag`."""
    return names_tag(request.headers.get("if-none-match"), tag)


def not_modified(tag: str) -> Response:
    """A 304 answer carrying the tag."""
    return Response(status_code=304, headers={"ETag": tag, **POLL_HEADERS})


def tag_answer(response: Response, tag: str) -> None:
    """Put the tag (and the revalidation rule) on a full answer."""
    response.headers["ETag"] = tag
    response.headers.update(POLL_HEADERS)


def _activity_tag(ctx: services.Context, token: str) -> str | None:
    return services.activity_tag(services.robot_activity(ctx, token))


# The polled paths and the current tag of each (None: let the app answer, e.g. 401 for an unknown token).
TAGGERS: dict[str, Callable[[services.Context, str], str | None]] = {
    "/api/v1/me": services.current_state_tag,
    "/api/v1/me/robot": _activity_tag,
}


class PollsNotModified:
    """ASGI middleware: a participant's conditional poll whose tag still holds is answered 304 here."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        tagger = TAGGERS.get(scope["path"]) if scope["type"] == "http" and scope["method"] == "GET" else None
        if tagger is not None:
            headers = dict(scope["headers"])
            known, auth = headers.get(b"if-none-match"), headers.get(b"authorization", b"")
            scheme, _, token = auth.decode("latin-1").partition(" ")
            if known and scheme.lower() == "bearer" and token.strip():
                try:
                    tag = await run_in_threadpool(tagger, scope["app"].state.context, token.strip())
                except TableTeachError:  # an unknown token, a busy database: the app gives its usual answer
                    tag = None
                if tag is not None and names_tag(known.decode("latin-1"), tag):
                    await send({"type": "http.response.start", "status": 304,
                                "headers": [(b"etag", tag.encode()),
                                            *((k.lower().encode(), v.encode()) for k, v in POLL_HEADERS.items())]})
                    await send({"type": "http.response.body", "body": b""})
                    return
        await self.app(scope, receive, send)
