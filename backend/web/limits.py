"""Request limits: bodies over MAX_BODY_BYTES get 413 before they are read, header blocks over
MAX_HEADER_BYTES get 431 while they are parsed (uvicorn's httptools parser has no limit of its own), and
connections whose headers are not complete within a deadline, or whose body stalls, are closed.

uvicorn 0.54 arms its only timer (keep-alive) after a response: a connection that never completes its first
request's headers is held for ever (measured: 1,100 of them used up every file descriptor). The timers here
live in the protocol object, on the event loop, so holding a connection costs no task or thread."""

from __future__ import annotations

import asyncio
import json
import math
import resource
import threading
import time
from collections import OrderedDict, deque
from typing import Any, cast

from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

MAX_BODY_BYTES = 1 << 20  # 1 MiB: the largest legitimate body (a study definition) is a few kilobytes
MAX_HEADER_BYTES = 32 << 10  # request line plus headers
HEADER_TIMEOUT_SECONDS = 10.0  # from a connection's (or a request's) first byte to the end of its headers
BODY_TIMEOUT_SECONDS = 10.0  # between two reads of a request body, as nginx's client_body_timeout


class AddressLimiter:
    """At most `limit` events (wrong keys, joins) per client address in a sliding `window`; then it waits."""

    def __init__(self, limit: int = 20, window: float = 60.0, max_clients: int = 10_000) -> None:
        self.limit, self.window, self.max_clients = limit, window, max_clients
        self._failures: OrderedDict[str, deque[float]] = OrderedDict()
        self._lock = threading.Lock()

    def _recent(self, client: str, now: float) -> deque[float] | None:
        times = self._failures.get(client)
        if times is None:
            return None
        while times and times[0] <= now - self.window:
            times.popleft()
        if not times:
            del self._failures[client]
            return None
        return times

    def retry_after(self, client: str) -> int:
        """Seconds this address must wait before its next attempt (0: it may try now)."""
        now = time.monotonic()
        with self._lock:
            times = self._recent(client, now)
            if times is None or len(times) < self.limit:
                return 0
            return max(1, math.ceil(times[0] + self.window - now))

    def record(self, client: str) -> None:
        """Count one event from this address (the oldest addresses are forgotten beyond max_clients)."""
        now = time.monotonic()
        with self._lock:
            times = self._recent(client, now) or deque()
            times.append(now)
            self._failures[client] = times
            self._failures.move_to_end(client)
            while len(self._failures) > self.max_clients:
                self._failures.popitem(last=False)


class BodyTooLarge(Exception):
    """The client sent more than the limit without announcing it in Content-Length."""


async def _refuse(send: Send, status: int, detail: str) -> None:
    body = json.dumps({"detail": detail, "state": None}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                            (b"connection", b"close")]})
    await send({"type": "http.response.body", "body": body})


class BodyLimit:
    """ASGI middleware: refuse a body over `limit` bytes with 413 (by Content-Length at once, else when reached)."""

    def __init__(self, app: ASGIApp, limit: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        detail = f"request body too large: expected at most {self.limit} bytes"
        length = dict(scope["headers"]).get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.limit):
            await _refuse(send, 413, detail)
            return
        seen = 0
        started = refused = False

        async def counted_receive() -> Message:
            nonlocal seen, refused
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    if not started and not refused:
                        refused = True
                        await _refuse(send, 413, detail)  # whatever the app makes of the error is dropped
                    raise BodyTooLarge(detail)
            return message

        async def tracked_send(message: Message) -> None:
            nonlocal started
            if refused:
                return
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except BodyTooLarge:
            if not refused:
                raise


class LimitedHttpToolsProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with a cap on the request line plus headers (431 beyond it), a deadline for
    complete headers (408 and closed) and one for each read of a body (closed)."""

    header_timeout = HEADER_TIMEOUT_SECONDS
    body_timeout = BODY_TIMEOUT_SECONDS

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._header_bytes = 0
        self._too_large = False
        self._deadline: asyncio.TimerHandle | None = None

    @classmethod
    def with_timeouts(cls, header_seconds: float, body_seconds: float) -> type[LimitedHttpToolsProtocol]:
        """This protocol with other deadlines (the server's settings)."""
        configured = type(cls.__name__, (cls,), {"header_timeout": header_seconds, "body_timeout": body_seconds})
        return cast("type[LimitedHttpToolsProtocol]", configured)

    def _arm(self, seconds: float, handler: Any) -> None:
        self._disarm()
        self._deadline = self.loop.call_later(seconds, handler)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _headers_too_slow(self) -> None:
        self._deadline = None
        if self.transport.is_closing():
            return
        if self.cycle is None or self.cycle.response_complete:  # nothing else is writing: say why
            body = f"request headers not complete within {self.header_timeout:g} s".encode()
            self.transport.write(b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain; charset=utf-8\r\n"
                                 b"content-length: " + str(len(body)).encode() + b"\r\nconnection: close\r\n\r\n"
                                 + body)
        self.transport.close()

    def _body_stalled(self) -> None:
        self._deadline = None
        if not self.transport.is_closing():
            self.transport.close()  # the application's receive() then reports a disconnect

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm(self.header_timeout, self._headers_too_slow)

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def _count(self, n: int) -> None:
        self._header_bytes += n
        if self._header_bytes > MAX_HEADER_BYTES:
            self._too_large = True
            raise ValueError(f"request headers over {MAX_HEADER_BYTES} bytes")

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._header_bytes = 0
        if self._deadline is None:  # the next request on a kept-alive connection: its headers have a deadline too
            self._arm(self.header_timeout, self._headers_too_slow)

    def on_url(self, url: bytes) -> None:
        self._count(len(url))
        super().on_url(url)

    def on_header(self, name: bytes, value: bytes) -> None:
        self._count(len(name) + len(value) + 4)
        super().on_header(name, value)

    def on_headers_complete(self) -> None:
        self._disarm()
        super().on_headers_complete()
        upgrading = self.parser.should_upgrade() and self._should_upgrade()
        length = dict(self.headers).get(b"content-length", b"0")
        chunked = b"chunked" in dict(self.headers).get(b"transfer-encoding", b"").lower()
        if not upgrading and (chunked or length.strip() not in (b"", b"0")):
            self._arm(self.body_timeout, self._body_stalled)

    def on_body(self, body: bytes) -> None:
        if self._deadline is not None:
            self._arm(self.body_timeout, self._body_stalled)
        super().on_body(body)

    def on_message_complete(self) -> None:
        self._disarm()
        super().on_message_complete()

    def send_400_response(self, msg: str) -> None:
        """The parser stopped: say 431 when it was our header limit, else uvicorn's 400."""
        self._disarm()
        if not self._too_large:
            super().send_400_response(msg)
            return
        body = f"request headers too large: expected at most {MAX_HEADER_BYTES} bytes".encode()
        self.transport.write(b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-type: text/plain; "
                             b"charset=utf-8\r\ncontent-length: " + str(len(body)).encode() +
                             b"\r\nconnection: close\r\n\r\n" + body)
        self.transport.close()


def raise_open_files_limit() -> tuple[int, int]:
    """Raise this process's soft limit on open files to its hard limit (every held connection is one); the
    limits now (soft, hard). Left as they are where the platform refuses."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
        except (ValueError, OSError):
            return soft, hard
    return resource.getrlimit(resource.RLIMIT_NOFILE)
