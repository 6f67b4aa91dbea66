"""One viser server per app process showing every participant's table: each browser is a viser client with a
scene of its own, so an open view costs a little state, not a server.

The tables and their labels are in the server's shared scene (the same for everyone); the arm, the objects
and the caption are in each client's own scene, written as viser's messages from a template made once per model
(sim/client_scene.py) rather than through viser's scene handles. A browser reaches the server only through the
app's websocket proxy, which checks the participant's token and connects to `/<ticket>`: a one-time ticket that
names the table. What this relies on of viser's private code is in sim/viser_private.py.

Clicks arrive on viser's event loop; the hub hands them to `on_click(key, obj)` on viser's executor, which must only
queue them. `on_leave(key)` runs on viser's event loop and must not block.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import viser

from .client_scene import ClientScene, SceneTemplate, template_key
from .view import BodyMirror, add_table_labels, moving_bodies, prepare_server
from .viser_private import (client_queue, let_sent_windows_go, on_scene_clicks, run_callback,
                            share_message_compressors, ticket_of)

log = logging.getLogger(__name__)
TICKET_SECONDS = 60.0  # a ticket is used by the proxy within milliseconds of being issued
TEMPLATES = 32  # scene templates kept (one per distinct scene: the dinner table's and each study's own)


@dataclass
class ClientView:
    """One browser's own scene of one table."""

    key: str
    client: viser.ClientHandle
    scene: ClientScene


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
        self._templates: dict[bytes, SceneTemplate] = {}  # template_key(model) -> its template

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
                view.scene.set_poses(bodies, poses)
        return len(targets)

    def play(self, key: str, bodies: Sequence[str], times: np.ndarray, poses: np.ndarray) -> int:
        """Send every browser showing this table a motion to play on its own clock (poses (frames, bodies, 7) at
        times in seconds from now); how many browsers."""
        targets = self._of(key)
        for view in targets:
            view.scene.play(bodies, times, poses)
        return len(targets)

    def set_caption(self, key: str, text: str) -> None:
        """The caption above this table in every browser showing it."""
        for view in self._of(key):
            view.scene.set_caption(text)

    def set_clickable(self, key: str, objects: frozenset[str]) -> None:
        """Exactly these objects report clicks in the browsers showing this table."""
        for view in self._of(key):
            view.scene.set_clickable(objects)

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
            let_sent_windows_go()
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
            on_scene_clicks(server, self._scene_clicked)
            self._server = server
            return server

    def _joined(self, client: viser.ClientHandle) -> None:
        server = self._server
        if server is None:
            return
        ticket = ticket_of(server, client.client_id)
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
        template = self._template_of(model)
        with client.atomic():
            scene = ClientScene(template, client_queue(client))
            scene.set_poses(bodies, poses)
            scene.set_caption(caption_text)
        scene.set_clickable(clickable)
        with self._lock:
            if self._server is None:
                return
            self._views[client.client_id] = ClientView(key, client, scene)
        if client.client_id not in server.get_clients():  # it left while joining: _left may have found nothing
            self._forget(client)
            return
        log.debug("viewer %s joined table %s", client.client_id, key)

    def _template_of(self, model: mujoco.MjModel) -> SceneTemplate:
        """The scene template of the model's scene, made on first use (a few milliseconds)."""
        key = template_key(model)
        with self._lock:
            template = self._templates.get(key)
        if template is None:
            template = SceneTemplate(model)
            with self._lock:
                while len(self._templates) >= TEMPLATES:
                    self._templates.pop(next(iter(self._templates)))
                template = self._templates.setdefault(key, template)
        return template

    async def _left(self, client: viser.ClientHandle) -> None:
        # async: viser runs it on its event loop, so closing many views at once starts no executor threads
        self._forget(client)

    def _forget(self, client: viser.ClientHandle) -> None:
        with self._lock:
            view = self._views.pop(client.client_id, None)
        if view is not None:
            self._on_leave(view.key)

    def _scene_clicked(self, client_id: int, node: str) -> None:
        with self._lock:
            view = self._views.get(client_id)
            server = self._server
        body = None if view is None else view.scene.clicked(node)
        if view is not None and body is not None and server is not None:
            run_callback(server, self._on_click, view.key, body)
