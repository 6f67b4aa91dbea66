"""Where the view hub relies on viser 1.1's private code, all in one place: viser is pinned in constraints.txt, and
tests/sim/test_view_hub.py fails if an upgrade changes any of what is used here.

- ticket_of: a connection's request path, known only to viser's websocket server (`_live_connections`).
- share_message_compressors: viser gives each client two zstd compressors (one per message producer, about 250 KiB
  of context each). Every producer runs on the server's one event loop and compresses in one synchronous call, so
  they can share one compressor per thread and level.
- let_sent_windows_go: viser's message producer keeps the last window it sent (its messages, their serialized form
  and the compressed bytes) in its frame until the next window; an idle view kept its whole scene that way, once for
  its own scene and once for the shared one. The producer installed here is viser's, except that a window is let go
  once it is sent.
- RecordingScene, client_queue, on_scene_clicks, run_callback: a browser's own scene made from messages recorded
  once per model (sim/client_scene.py) instead of viser's scene handles, and its clicks.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import msgspec
import viser
from viser import _messages as viser_messages
from viser.infra import _infra

log = logging.getLogger(__name__)


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
    if not isinstance(_infra.zstandard, SharedCompressors):
        setattr(_infra, "zstandard", SharedCompressors(_infra.zstandard))  # noqa: B010 (a module attribute)


def window_bytes(outgoing: Sequence[Any], compressor: Any) -> bytes:
    """One window of messages in viser 1.1's wire format (zstd-compressed msgpack, then the aligned binary buffers),
    made as viser's _message_producer makes it."""
    binary_buffers: list[memoryview] = []
    serialized_messages = tuple(message.as_serializable_dict(binary_buffers) for message in outgoing)
    inner = msgspec.msgpack.encode({"messages": serialized_messages, "timestampSec": time.perf_counter(),
                                    "binaryBufferLengths": tuple(b.nbytes for b in binary_buffers)})
    compressed = compressor.compress(inner)
    parts: list[bytes | memoryview] = [len(inner).to_bytes(8, "little"), len(compressed).to_bytes(8, "little"),
                                       compressed]
    _infra._append_aligned_buffers(parts, binary_buffers, 16 + len(compressed))
    return b"".join(parts)


async def _message_producer(websocket: Any, buffer: Any, client_id: int, backlog_done_message: Any = None) -> None:
    """viser 1.1's _message_producer, letting each window go once it is sent."""
    window_generator = buffer.window_generator(client_id, backlog_done_message=backlog_done_message)
    compressor = _infra.zstandard.ZstdCompressor(level=1)
    try:
        while not buffer.done:
            try:
                outgoing = await window_generator.__anext__()
            except StopAsyncIteration:
                break
            payload = window_bytes(outgoing, compressor)
            del outgoing  # an idle view waits for its next window without this one
            await websocket.send(payload)
            del payload
    finally:
        await window_generator.aclose()


VISERS_PRODUCER = _infra._message_producer


def let_sent_windows_go() -> None:
    """Make viser's connections use the producer that lets a sent window go (see the module's docstring)."""
    setattr(_infra, "_message_producer", _message_producer)  # noqa: B010 (a module attribute)


class RecordingScene(viser.SceneApi):
    """A scene of no server and no client: viser's own add_* methods and handles work on it, and every message
    they would send is kept in `messages` instead."""

    def __init__(self) -> None:  # viser's __init__ needs a server or a client: set what adding nodes uses
        self.messages: list[Any] = []
        self._node_lifecycle_lock = threading.RLock()
        self._handle_from_node_name = {}
        self._children_from_node_name = {}
        self._creating_virtual_anchors = False

    def _queue_scene_message(self, message: Any) -> None:
        self.messages.append(message)


def client_queue(client: viser.ClientHandle) -> Callable[[Any], None]:
    """Queue a scene message to one client, stamped as its own scene's (as its scene handles would)."""
    queue: Callable[[Any], None] = client.scene._queue_scene_message
    return queue


def on_scene_clicks(server: viser.ViserServer, callback: Callable[[int, str], None]) -> None:
    """Call callback(client id, node name) for each plain left click on a node of a client's own scene; on viser's
    event loop, so it must only look up and hand over (run_callback)."""

    def clicked(client_id: int, message: viser_messages.SceneNodeClickMessage) -> None:
        if message.owner == str(client_id) and message.modifier is None:
            callback(client_id, message.name)

    server._websock_server.register_handler(viser_messages.SceneNodeClickMessage, clicked)


def run_callback(server: viser.ViserServer, fn: Callable[..., None], *args: Any) -> None:
    """Run fn(*args) on viser's executor, where it runs the callbacks of scene handles."""

    def run() -> None:
        try:
            fn(*args)
        except Exception:
            log.exception("a view's callback failed")

    server._thread_executor.submit(run)
