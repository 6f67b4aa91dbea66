"""The participant page's change notices as server-sent events (/p/{token}/events), shared per participant.

Each participant with open streams has one ParticipantFeed: it waits on the notifier and, per change, reads
the robot's activity once; every open stream of that participant sends the same event. A participant may
hold streams_per_participant streams (a newer one ends the oldest with a `superseded` event, after which the
page polls); the process holds max_event_streams (beyond: 503 with Retry-After, and the page polls)."""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, PlainTextResponse, Response, StreamingResponse
from starlette.concurrency import run_in_threadpool
from starlette.types import Receive, Scope, Send

from .. import services
from ..errors import NotAuthenticated
from .deps import ContextDep
from .streams import Slot, StreamSlots

log = logging.getLogger(__name__)
router = APIRouter(tags=["participant page"])
EVENTS_KEEPALIVE_SECONDS = 15.0  # a comment line this often keeps proxies from closing a quiet stream
EVENTS_STREAM_SECONDS = 300.0  # then the stream ends and the browser reconnects (a restart never waits on it)
EVENTS_RETRY_MS = 1000
STORED_CLOCK_GRACE_SECONDS = 0.3  # a timer's notice of an action end normally comes first; this is the back-up
FULL_RETRY_SECONDS = 30
SUPERSEDED = "event: superseded\ndata: {}\n\n"

Reader = Callable[[], Awaitable[services.ChangeSnapshot | None]]  # None: the read failed


def change_event(counter: int, snapshot: services.ChangeSnapshot | None) -> str:
    """The text of one change event: the change counter, the robot's activity and the state's tag (both null when
    the read failed: the page then reads everything)."""
    data = {"n": counter, "robot": snapshot.robot if snapshot else None,
            "state": snapshot.state_tag if snapshot else None}
    return f"event: change\ndata: {json.dumps(data, separators=(',', ':'))}\n\n"


@dataclass(eq=False)
class ParticipantFeed:
    """One participant's change events: one read per change, handed to every open stream of theirs."""

    pid: int
    notifier: services.LocalNotifier
    read: Reader
    streams: set[Slot] = field(default_factory=set)
    event: str = ""
    version: int = 0
    reads: int = 0
    ready: asyncio.Event = field(default_factory=asyncio.Event)
    task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Begin following the notifier (on the running event loop)."""
        self.task = asyncio.ensure_future(self._follow())
        self.task.add_done_callback(_log_failure)

    def _publish(self, counter: int, snapshot: services.ChangeSnapshot | None) -> None:
        self.event = change_event(counter, snapshot)
        self.version += 1
        self.ready.set()
        for slot in self.streams:
            slot.wake.set()

    async def _read(self) -> tuple[services.ChangeSnapshot | None, float | None]:
        self.reads += 1
        snapshot = await self.read()
        return snapshot, None if snapshot is None else snapshot.next_change_in

    async def _follow(self) -> None:
        """An event at once, then one per change; the stored plan's next action end is the back-up clock (the
        process whose timer announces it may have gone)."""
        seen = self.notifier.counter(self.pid)
        snapshot, due = await self._read()
        self._publish(seen, snapshot)
        while True:
            due_at = None if due is None else time.monotonic() + due + STORED_CLOCK_GRACE_SECONDS
            wait = EVENTS_KEEPALIVE_SECONDS if due_at is None else max(0.0, due_at - time.monotonic())
            current = await self.notifier.wait(self.pid, seen, min(wait, EVENTS_KEEPALIVE_SECONDS))
            if current == seen and (due_at is None or time.monotonic() < due_at):
                continue
            seen = current
            snapshot, due = await self._read()
            self._publish(seen, snapshot)

    def stop(self) -> None:
        """No stream follows this participant any more."""
        if self.task is not None:
            self.task.cancel()


def _log_failure(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("a participant's change feed stopped", exc_info=task.exception())


class Feeds:
    """The feeds of the participants with open streams, and the slots of those streams."""

    def __init__(self, slots: StreamSlots) -> None:
        self.slots = slots
        self._feeds: dict[int, ParticipantFeed] = {}

    def feed(self, pid: int) -> ParticipantFeed | None:
        """The feed of a participant while they have an open stream."""
        return self._feeds.get(pid)

    def open(self, pid: int, notifier: services.LocalNotifier, read: Reader) -> tuple[ParticipantFeed, Slot] | None:
        """A new stream of this participant (ending their oldest beyond the limit); None when the process is full."""
        slot = self.slots.take(pid)
        if slot is None:
            return None
        feed = self._feeds.get(pid)
        if feed is None or (feed.task is not None and feed.task.done()):  # a feed whose loop failed starts again
            feed = self._feeds[pid] = ParticipantFeed(pid, notifier, read)
            feed.start()
        feed.streams.add(slot)
        return feed, slot

    def close(self, feed: ParticipantFeed, slot: Slot) -> None:
        """A stream ended (again is harmless); the feed stops with its last stream."""
        self.slots.release(slot)
        feed.streams.discard(slot)
        if not feed.streams and self._feeds.get(feed.pid) is feed:
            del self._feeds[feed.pid]
            feed.stop()


async def stream(feeds: Feeds, feed: ParticipantFeed, slot: Slot,
                 seconds: float = EVENTS_STREAM_SECONDS) -> AsyncIterator[str]:
    """One open stream: the latest event at once, then each new one; keep-alive comments between; a
    `superseded` event if a newer stream of the participant took its place; ends after `seconds`.

    Its slot is given back when it ends; HeldStream also gives it back if the stream never started."""
    try:
        if not await _ready(feed):
            return  # the feed failed before its first read (logged there): the browser reconnects to a new one
        sent = feed.version
        yield f"retry: {EVENTS_RETRY_MS}\n" + feed.event
        ends = time.monotonic() + seconds
        while (left := ends - time.monotonic()) > 0:
            quiet = False
            if feed.version == sent and not slot.superseded:
                slot.wake.clear()
                try:
                    await asyncio.wait_for(slot.wake.wait(), min(EVENTS_KEEPALIVE_SECONDS, left))
                except asyncio.TimeoutError:
                    quiet = True
            if slot.superseded:
                yield SUPERSEDED
                return
            if feed.version != sent:
                sent = feed.version
                yield feed.event
            elif feed.task is not None and feed.task.done():
                return  # the feed failed (logged there): the browser reconnects to a new one
            elif quiet:
                yield ": still here\n\n"
    finally:
        feeds.close(feed, slot)


async def _ready(feed: ParticipantFeed) -> bool:
    """Wait for the feed's first event; False if the feed stopped before it."""
    if feed.ready.is_set() or feed.task is None:
        await feed.ready.wait()
        return True
    waiter = asyncio.ensure_future(feed.ready.wait())
    try:
        await asyncio.wait({waiter, feed.task}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        waiter.cancel()
    return feed.ready.is_set()


class HeldStream(StreamingResponse):
    """A streaming response that runs `on_end` however it ends, even when the client left before the first byte
    (then the body's generator never starts, so its own clean-up never runs)."""

    def __init__(self, content: AsyncIterator[str], on_end: Callable[[], None], **kwargs: Any) -> None:
        super().__init__(content, **kwargs)
        self._on_end = on_end

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            self._on_end()


def feeds_of(request: Request) -> Feeds:
    """The app's feeds (made with the app, from its settings)."""
    return request.app.state.event_feeds


@router.get("/p/{token}/events", include_in_schema=False)
async def change_events(token: str, ctx: ContextDep, request: Request) -> Response:
    """Server-sent events: `change` whenever the participant's state or robot changes.

    Each event's data is {"n": change counter, "robot": GET /me/robot's answer, "state": GET /api/v1/me's ETag
    now}, so the page shows the robot busy at once without asking, and reads its state only when the tag differs
    from the one it holds. EventSource cannot send an Authorization
    header, so the token comes from the page's own path (the page's address carries it already).
    """
    try:
        pid = await run_in_threadpool(services.participant_id_of, ctx, token)  # one query: the feed reads the rest
    except NotAuthenticated:
        return HTMLResponse("<p>No participant has this link.</p>", status_code=404)

    def read() -> services.ChangeSnapshot | None:
        try:
            return services.change_snapshot(ctx, token)
        except Exception:  # a head start and a back-up clock for the page; without it the page reads everything
            log.exception("the change snapshot for a change event failed")
            return None

    feeds = feeds_of(request)
    opened = feeds.open(pid, ctx.notifier, lambda: run_in_threadpool(read))
    if opened is None:
        return PlainTextResponse("too many open event streams on this server; the page checks for changes by "
                                 "itself meanwhile", status_code=503,
                                 headers={"Retry-After": str(FULL_RETRY_SECONDS), "Cache-Control": "no-store"})
    headers = {"Cache-Control": "no-store", "X-Accel-Buffering": "no", "Referrer-Policy": "no-referrer"}
    return HeldStream(stream(feeds, *opened), lambda: feeds.close(*opened), media_type="text/event-stream",
                      headers=headers)
