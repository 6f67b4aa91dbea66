"""create_app(settings): composes the routers, the services context and the error mapping; nothing global."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from typing import Any

from fastapi import APIRouter, FastAPI

from ..config import Settings
from ..services import Context, app_version
from . import errors, exports, pages, participants, studies
from . import analysis, dashboard, instruments, motion, viewer
from .auth import FailureLimiter, experimenter_checker
from .deps import require_experimenter
from .limits import BodyLimit
from .robots import make_robot
from .schemas import error_responses

DESCRIPTION = """Study server for teaching a robot to set a dinner table from demonstrations and verdicts.

Participants authenticate with the token from their link (`Authorization: Bearer <token>`);
experimenters with the server's experimenter token. Every participant action accepts an
`Idempotency-Key` header: repeating a request with the same key changes nothing. See docs/server.md."""


def _common_errors(router: APIRouter) -> dict[int | str, dict[str, Any]]:
    """Answers any route of the router can give: 413 (body too large), 503 (database busy or gone) and, behind
    the experimenter key, 429 (too many wrong keys)."""
    codes = [413, 503]
    if any(getattr(dep, "dependency", None) is require_experimenter for dep in router.dependencies):
        codes.append(429)
    return error_responses(*codes)


def create_app(settings: Settings, *, context: Context | None = None) -> FastAPI:
    """The FastAPI application for these settings (ValueError if the experimenter secret is unacceptable)."""
    checker, dev_token = experimenter_checker(settings)
    ctx = context or Context.from_settings(settings, make_robot(settings))

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        yield
        ctx.planner.shutdown()
        ctx.placements.shutdown()  # placements under way end first: they use the robot and the database
        ctx.notifier.close()  # PgNotifier: its LISTEN and NOTIFY connections
        shutdown = getattr(ctx.robot, "shutdown", None)  # the MuJoCo robot stops its viser servers
        if shutdown is not None:
            shutdown()
        ctx.db.dispose()

    # /docs and /redoc load their scripts from a CDN: offered in dev mode only (/openapi.json is always served).
    docs = {} if settings.dev_mode else {"docs_url": None, "redoc_url": None}
    app = FastAPI(title="TableTeach study server", version=app_version(), description=DESCRIPTION, lifespan=lifespan,
                  **docs)
    app.state.context = ctx
    app.state.settings = settings
    app.state.experimenter = checker
    app.state.dev_token = dev_token
    app.state.key_failures = FailureLimiter()
    errors.install(app)
    app.add_middleware(BodyLimit)
    for module in (participants, studies, exports, analysis, dashboard, motion, viewer, pages, instruments):
        app.include_router(module.router, responses=_common_errors(module.router))
    app.include_router(studies.formulas, responses=_common_errors(studies.formulas))
    return app
