"""create_app(settings): composes the routers, the services context and the error mapping; nothing global."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from typing import Any

from fastapi import APIRouter, FastAPI

from ..config import Settings
from ..services import Context, app_version
from . import errors, exports, pages, participants, studies
from . import accounts, analysis, dashboard, events, instruments, motion, openapi, prolific, viewer
from .audit import AuditWrites
from .auth import experimenter_checker
from .conditional import PollsNotModified
from .deps import require_experimenter
from .events import Feeds
from .limits import AddressLimiter, BodyLimit
from .methods import AllowedMethods, route_table
from .robots import make_recording_store, make_robot
from .streams import StreamSlots
from .schemas import error_responses

DESCRIPTION = """Study server for teaching a robot to set a dinner table from demonstrations and verdicts.

Participants authenticate with the token from their link (`Authorization: Bearer <token>`);
experimenters with the server's experimenter token. Every participant action accepts an
`Idempotency-Key` header: repeating a request with the same key changes nothing. See docs/server.md."""


def _common_errors(router: APIRouter) -> dict[int | str, dict[str, Any]]:
    """Answers any route of the router can give: 413 (body too large), 503 (database busy or gone) and, behind
    the experimenter key, 403 (a role that may not) and 429 (too many wrong keys)."""
    codes = [413, 503]
    if any(getattr(dep, "dependency", None) is require_experimenter for dep in router.dependencies):
        codes += [403, 429]
    return error_responses(*codes)


def create_app(settings: Settings, *, context: Context | None = None) -> FastAPI:
    """The FastAPI application for these settings (ValueError if the experimenter secret is unacceptable)."""
    checker, dev_token = experimenter_checker(settings)
    ctx = context or Context.from_settings(settings, make_robot(settings),
                                          lambda db: make_recording_store(settings, db))

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        ctx.start()  # the runtime: job runners (durable background work), scheduler, action queue, robot
        route_table(_app)  # FastAPI resolves its routes on first use (~0.3 s of CPU): at start-up, not in a request
        yield
        ctx.close()  # handlers under way end; the robot, the notifier's connections and the database close

    # /docs and /redoc load their scripts from a CDN: offered in dev mode only (/openapi.json is always served).
    docs = {} if settings.dev_mode else {"docs_url": None, "redoc_url": None}
    app = FastAPI(title="TableTeach study server", version=app_version(), description=DESCRIPTION, lifespan=lifespan,
                  generate_unique_id_function=openapi.operation_id, **docs)
    app.state.context = ctx
    app.state.settings = settings
    app.state.experimenter = checker
    app.state.dev_token = dev_token
    app.state.key_failures = AddressLimiter()
    app.state.joins = AddressLimiter(settings.joins_per_address, settings.joins_window_seconds)
    app.state.event_feeds = Feeds(StreamSlots(settings.streams_per_participant, settings.max_event_streams))
    app.state.viewer_slots = StreamSlots(settings.streams_per_participant, settings.max_viewer_sockets)
    errors.install(app)
    openapi.install(app)
    app.add_middleware(BodyLimit)
    app.add_middleware(AuditWrites)
    app.add_middleware(AllowedMethods, routes_of=lambda: app)
    app.add_middleware(PollsNotModified)  # outermost of ours: a poll that finds nothing new ends here
    for module in (participants, studies, exports, analysis, accounts, prolific, dashboard, motion, viewer, events,
                   pages, instruments):
        app.include_router(module.router, responses=_common_errors(module.router))
    app.include_router(studies.formulas, responses=_common_errors(studies.formulas))
    app.include_router(accounts.public, responses=_common_errors(accounts.public))
    return app
