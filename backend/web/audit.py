"""The audit log's middleware: every experimenter write (not GET/HEAD/OPTIONS) is recorded with who made it, what
it was, its answer's status, when and from which address, once the answer is sent."""

from __future__ import annotations

import logging
from typing import Any

from starlette.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..errors import TableTeachError
from ..services import accounts

log = logging.getLogger(__name__)


class AuditWrites:
    """ASGI middleware: after a write request that an experimenter made (request.state.experimenter), append it to
    the audit log."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in accounts.READ_METHODS:
            await self.app(scope, receive, send)
            return
        status = 500

        async def remember_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, remember_status)
        finally:
            actor: Any = scope.get("state", {}).get("experimenter")
            if isinstance(actor, accounts.Actor):
                client = scope["client"][0] if scope.get("client") else "unknown"
                try:
                    await run_in_threadpool(accounts.record_write, scope["app"].state.context, actor, scope["method"],
                                            scope["path"], status, client)
                except TableTeachError:
                    log.exception("could not write the audit entry of %s %s by %s", scope["method"], scope["path"],
                                  actor.name)
