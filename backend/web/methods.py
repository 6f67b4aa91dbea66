"""OPTIONS and 405 answers that name every method of a path (RFC 9110 15.5.6): Starlette answers 405 per route,
so where a path has two routes (GET and PATCH /studies/{id}) its Allow header would name only one."""

from __future__ import annotations

import re
from collections.abc import Callable, MutableMapping
from typing import Any

from fastapi.routing import iter_route_contexts
from starlette.routing import compile_path
from starlette.types import ASGIApp, Receive, Scope, Send

Message = MutableMapping[str, Any]


def route_table(app: Any) -> list[tuple[re.Pattern[str], frozenset[str]]]:
    """Each HTTP route of the app (included routers' too) as its path pattern and methods."""
    table = []
    for route in iter_route_contexts(app.routes):
        if route.path and route.methods:
            pattern, _, _ = compile_path(route.path)
            table.append((pattern, frozenset(route.methods)))
    return table


def allowed_methods(table: list[tuple[re.Pattern[str], frozenset[str]]], path: str) -> list[str]:
    """Every method the app answers at this path (HEAD with GET, and OPTIONS); empty for an unknown path."""
    methods: set[str] = set()
    for pattern, route_methods in table:
        if pattern.match(path):
            methods |= route_methods
    if methods:
        methods.add("OPTIONS")
    return sorted(methods)


class AllowedMethods:
    """Answer OPTIONS with 204 and Allow; complete the Allow header of every 405."""

    def __init__(self, app: ASGIApp, routes_of: Callable[[], Any]) -> None:
        self.app = app
        self.routes_of = routes_of  # the FastAPI app (its routes are known once it is built)
        self.table: list[tuple[re.Pattern[str], frozenset[str]]] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if self.table is None:
            self.table = route_table(self.routes_of())
        methods = allowed_methods(self.table, scope["path"])
        if scope["method"] == "OPTIONS" and methods:
            await send({"type": "http.response.start", "status": 204,
                        "headers": [(b"allow", ", ".join(methods).encode())]})
            await send({"type": "http.response.body", "body": b""})
            return

        async def send_with_allow(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405 and methods:
                headers = [(k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"]
                message = {**message, "headers": [*headers, (b"allow", ", ".join(methods).encode())]}
            await send(message)

        await self.app(scope, receive, send_with_allow)


