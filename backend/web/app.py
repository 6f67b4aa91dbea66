"""create_app(settings): composes the routers, the services context and the error mapping; nothing global."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from ..config import Settings
from ..services import Context, app_version
from . import errors, exports, pages, participants, studies
from . import analysis, dashboard, motion, viewer
from .auth import experimenter_checker

DESCRIPTION = """Study server for teaching a robot to set a dinner table from demonstrations and verdicts.

Participants authenticate with the token from their link (`Authorization: Bearer <token>`);
experimenters with the server's experimenter token. Every participant action accepts an
`Idempotency-Key` header: repeating a request with the same key changes nothing. See docs/server.md."""


def create_app(settings: Settings, *, context: Context | None = None) -> FastAPI:
    """The FastAPI application for these settings (ValueError if the experimenter secret is unacceptable)."""
    checker, dev_token = experimenter_checker(settings)
    ctx = context or Context.from_settings(settings)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        yield
        ctx.planner.shutdown()
        shutdown = getattr(ctx.robot, "shutdown", None)  # the MuJoCo robot stops its viser servers
        if shutdown is not None:
            shutdown()
        ctx.db.dispose()

    app = FastAPI(title="TableTeach study server", version=app_version(), description=DESCRIPTION, lifespan=lifespan)
    app.state.context = ctx
    app.state.settings = settings
    app.state.experimenter = checker
    app.state.dev_token = dev_token
    errors.install(app)
    for module in (participants, studies, exports, analysis, dashboard, motion, viewer, pages):
        app.include_router(module.router)
    return app
