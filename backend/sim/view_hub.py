"""One viser server per app process showing every participant's table: each browser is a viser client with a
scene of its own (viser's per-client scene API), so an open view costs a few scene handles, not a server.

The tables and their labels are in the server's shared scene (the same for everyone); the arm, the objects
and the caption are in each client's own scene. A browser reaches the server only through the app's
websocket proxy, which checks the participant's token and connects to `/<ticket>`: a one-time ticket that
names the table. viser 1.1 gives a connection's request path only through its websocket server's live
connections (`_live_connections`, a private attribute): `ticket_of` is the one place that reads it, and
tests/sim/test_view_hub.py fails if a viser upgrade changes it (viser is pinned in constraints.txt).

viser 1.1 also gives each client two zstd compressors (one per message producer, about 250 KiB of context each:
two thirds of what an idle view cost). Every producer runs on the server's one event loop and compresses in one
synchronous call, so `share_message_compressors` makes them share one compressor per thread and level; the same
test fails if viser stops making them the way this expects.

Clicks arrive on viser's threads; the hub hands them to `on_click(key, obj)`, which must only queue them.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import viser

from .view import BodyMirror, add_caption, add_table_labels, moving_bodies, prepare_server

log = logging.getLogger(__name__)
TICKET_SECONDS = 60.0  # a ticket is used by the proxy within milliseconds of being issued


@dataclass
class ClientView:
    """One browser's own scene of one table."""

    key: str
    client: viser.ClientHandle
    mirror: BodyMirror
    caption: viser.LabelHandle
    clickable: set[str] = field(default_factory=set)


def ticket_of(server: viser.ViserServer, client_id: int) -> str | None:
    """The ticket in the request path of a connected client's websocket (None if viser does not say)."""
    live = getattr(getattr(server, "_websock_server", None), "_live_connections", None)
    connection = None if live is None else live.get(client_id)
    request = getattr(connection, "request", None)
    path = getattr(request, "path", None)
    if not isinstance(path, str):
        return None
    return path.strip("/").partition("?")[0] or None


class SharedCompressors:
    """Stands in for the zstandard module inside viser's connection code: ZstdCompressor(level=L) gives one
    compressor per thread and level; everything else is the module's own."""

    def __init__(self, module: Any) -> None:
        self.module = module
        self._local = threading.local()
        self.made = 0  # compressors made (one per thread and level that asked)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.module, name)

    def ZstdCompressor(self, level: int = 3, **options: Any) -> Any:  # noqa: N802 (the module's own name)
        """The thread's compressor of this level (a fresh one when given other options)."""
        if options:
            return self.module.ZstdCompressor(level=level, **options)
        cache: dict[int, Any] = self._local.__dict__.setdefault("compressors", {})
        if level not in cache:
            cache[level] = self.module.ZstdCompressor(level=level)
            self.made += 1
        return cache[level]


def share_message_compressors() -> None:
    """Make viser's per-client message producers share their zstd compressors (see the module's docstring)."""
    from viser.infra import _infra

    if not isinstance(_infra.zstandard, SharedCompressors):
        setattr(_infra, "zstandard", SharedCompressors(_infra.zstandard))  # noqa: B010 (a module attribute)


class ViewHub:
    """The process's viser server; tables are keyed by the robot's key. Thread-safe."""

    def __init__(self, model: mujoco.MjModel, *,
                 on_join: Callable[[str], tuple[Sequence[str], np.ndarray, str, frozenset[str], mujoco.MjModel] | None],
                 on_click: Callable[[str, str], None], on_leave: Callable[[str], None]) -> None:
        self._model = model
        # key -> (bodies, poses, caption, clickable objects, the table's model) for a new client, or None
        self._on_join = on_join
        self._on_click = on_click
        self._on_leave = on_leave
        self._moving = moving_bodies(model)
        self._lock = threading.Lock()
        self._tickets: dict[str, tuple[str, float]] = {}
        self._views: dict[int, ClientView] = {}
        self._server: viser.ViserServer | None = None
        self._rests: dict[int, tuple[mujoco.MjModel, mujoco.MjData]] = {}  # id(model) -> its rest pose

    @property
    def started(self) -> bool:
        """Whether the viser server is running."""
        return self._server is not None

    def port(self) -> int:
        """The local port of the viser server (started on first use)."""
        return self._ensure_server().get_port()

    def ticket(self, key: str) -> str:
        """A one-time ticket naming the table, for the proxy's connection path."""
        self._ensure_server()
        ticket = secrets.token_urlsafe(18)
        now = time.monotonic()
        with self._lock:
            self._tickets = {t: v for t, v in self._tickets.items() if v[1] > now}
            self._tickets[ticket] = (key, now + TICKET_SECONDS)
        return ticket

    def watchers(self, key: str) -> int:
        """Browsers showing this table now."""
        with self._lock:
            return sum(1 for view in self._views.values() if view.key == key)

    def clients(self, key: str) -> list[viser.ClientHandle]:
        """The viser clients showing this table (for tests and tools that look: never move anything through them)."""
        return [view.client for view in self._of(key)]

    def views(self) -> int:
        """Browsers connected to any table."""
        with self._lock:
            return len(self._views)

    def show(self, key: str, bodies: Sequence[str], poses: np.ndarray) -> int:
        """Push poses to every browser showing this table; how many browsers."""
        targets = self._of(key)
        for view in targets:
            with view.client.atomic():
                view.mirror.set_poses(bodies, poses)
        return len(targets)

    def set_caption(self, key: str, text: str) -> None:
        """The caption above this table in every browser showing it."""
        for view in self._of(key):
            view.caption.text = text
            view.caption.visible = bool(text)

    def set_clickable(self, key: str, objects: frozenset[str]) -> None:
        """Exactly these objects report clicks in the browsers showing this table."""
        for view in self._of(key):
            self._clickable(view, objects)

    def drop(self, key: str) -> None:
        """Forget the table's tickets (its browsers stay until they disconnect; they show nothing new)."""
        with self._lock:
            self._tickets = {t: v for t, v in self._tickets.items() if v[0] != key}

    def close(self) -> None:
        """Stop the server."""
        with self._lock:
            server, self._server = self._server, None
            self._views.clear()
            self._tickets.clear()
        if server is not None:
            server.stop()

    # -- internals -------------------------------------------------------------------------------------
    def _of(self, key: str) -> list[ClientView]:
        with self._lock:
            return [view for view in self._views.values() if view.key == key]

    def _ensure_server(self) -> viser.ViserServer:
        with self._lock:
            if self._server is not None:
                return self._server
            share_message_compressors()
            server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
            prepare_server(server, self._model)
            data = mujoco.MjData(self._model)
            mujoco.mj_forward(self._model, data)
            static = [self._model.body(b).name for b in range(self._model.nbody)
                      if self._model.body(b).name not in self._moving]
            BodyMirror(server.scene, self._model, data, static)
            add_table_labels(server.scene, self._model, data)
            server.on_client_connect(self._joined)
            server.on_client_disconnect(self._left)
            self._server = server
            return server

    def _joined(self, client: viser.ClientHandle) -> None:
        server = self._server
        ticket = None if server is None else ticket_of(server, client.client_id)
        now = time.monotonic()
        with self._lock:
            entry = self._tickets.pop(ticket, None) if ticket else None
        if entry is None or entry[1] < now:
            log.warning("a viewer connected without a valid ticket: it is shown the empty tables only")
            return
        key = entry[0]
        shown = self._on_join(key)
        if shown is None:
            return
        # The shared scene holds what every table has (tables, the robot's pedestal); the client's own scene the
        # moving bodies of its table's model (the dinner objects, or the study's own).
        bodies, poses, caption_text, clickable, model = shown
        with client.atomic():
            mirror = BodyMirror(client.scene, model, self._rest_of(model), moving_bodies(model))
            mirror.set_poses(bodies, poses)
            caption = add_caption(client.scene)
            caption.text, caption.visible = caption_text, bool(caption_text)
        view = ClientView(key, client, mirror, caption)
        self._clickable(view, clickable)
        with self._lock:
            if self._server is None:
                return
            self._views[client.client_id] = view
        log.debug("viewer %s joined table %s", client.client_id, key)

    def _rest_of(self, model: mujoco.MjModel) -> mujoco.MjData:
        """The model's rest pose, made once per scene (every new view's bodies start there; read only)."""
        with self._lock:
            entry = self._rests.get(id(model))
            if entry is None:
                data = mujoco.MjData(model)
                mujoco.mj_forward(model, data)
                entry = self._rests[id(model)] = (model, data)  # the model kept alive: its id stays its own
            return entry[1]

    def _left(self, client: viser.ClientHandle) -> None:
        with self._lock:
            view = self._views.pop(client.client_id, None)
        if view is not None:
            self._on_leave(view.key)

    def _clickable(self, view: ClientView, objects: frozenset[str]) -> None:
        for obj in set(view.mirror.geoms) & (objects ^ view.clickable):
            for handle in view.mirror.geoms[obj]:
                if obj in objects:
                    handle.on_click(lambda _event, key=view.key, name=obj: self._on_click(key, name))
                else:
                    handle.remove_click_callback("all")
        view.clickable = set(objects) & set(view.mirror.geoms)
