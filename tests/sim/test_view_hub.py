"""The process's one viser server (ViewHub): each browser gets its own table's scene by its one-time ticket, a
connection without a valid ticket sees the empty tables only, leaving is reported, and every browser's message
producers share one compressor. The two places that rely on viser's private code fail here if an upgrade
changes it: the ticket in the connection's path (ticket_of) and the compressor the producers make."""

from __future__ import annotations

import inspect
from collections.abc import Iterator

import msgpack
import numpy as np
import pytest
import viser
from websockets.sync.client import ClientConnection, connect

from tableteach.sim.scene import load_scene
from tableteach.sim.view_hub import SharedCompressors, ViewHub
from tests.waiting import wait_until

CAMERA = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [2.0, 0.0, 1.5],
          "image_height": 600, "image_width": 800, "fov": 0.9, "near": 0.01, "far": 100.0,
          "look_at": [0.0, 0.0, 0.4], "up_direction": [0.0, 0.0, 1.0]}


@pytest.fixture
def hub() -> Iterator[tuple[ViewHub, list[str], list[str]]]:
    """A hub whose tables all show the arm at rest; it records who joined and left."""
    model, _ = load_scene()
    joined: list[str] = []
    left: list[str] = []

    def on_join(key: str) -> tuple[list[str], np.ndarray, str, frozenset[str], object] | None:
        joined.append(key)
        return [], np.zeros((0, 7)), f"table {key}", frozenset({"bowl"}), model

    view_hub = ViewHub(model, on_join=on_join, on_click=lambda key, obj: None, on_leave=left.append)
    try:
        yield view_hub, joined, left
    finally:
        view_hub.close()


def _browser(hub: ViewHub, path: str) -> ClientConnection:
    """A connection as viser's browser client makes it (its protocol version, then a camera message)."""
    ws = connect(f"ws://127.0.0.1:{hub.port()}/{path}", subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
                 max_size=None, compression=None)
    ws.send(msgpack.packb(CAMERA))
    return ws


def test_each_browser_sees_its_own_table_by_ticket_and_leaving_is_reported(hub) -> None:
    view_hub, joined, left = hub
    first = _browser(view_hub, view_hub.ticket("1/0"))
    second = _browser(view_hub, view_hub.ticket("2/0"))
    wait_until(lambda: view_hub.views() == 2, "both browsers to join their tables")
    assert sorted(joined) == ["1/0", "2/0"] and view_hub.watchers("1/0") == view_hub.watchers("2/0") == 1

    stranger = _browser(view_hub, "not-a-ticket")
    wait_until(lambda: len(view_hub._server.get_clients()) == 3, "the third connection")  # type: ignore[union-attr]
    assert view_hub.views() == 2 and len(joined) == 2  # shown the empty tables only

    first.close()
    wait_until(lambda: left == ["1/0"], "the first browser's leaving to be reported")
    assert view_hub.views() == 1 and view_hub.watchers("2/0") == 1
    second.close()
    stranger.close()
    wait_until(lambda: view_hub.views() == 0, "every view to be gone")


def test_every_browsers_message_producers_share_one_compressor(hub) -> None:
    from viser.infra import _infra

    source = inspect.getsource(_infra._message_producer)
    assert "zstandard.ZstdCompressor(level=1)" in source, "viser now makes its producers' compressors otherwise"
    view_hub, _, _ = hub
    view_hub.port()  # the server starts
    shared = _infra.zstandard
    assert isinstance(shared, SharedCompressors)
    before = shared.made  # servers of other tests (each has an event loop thread of its own) made theirs
    browsers = [_browser(view_hub, view_hub.ticket(f"{i}/0")) for i in range(3)]
    wait_until(lambda: view_hub.views() == 3, "three browsers to join")
    # Six producers (two per browser), one compressor: made once on this server's event loop thread.
    wait_until(lambda: shared.made > before, "the producers to ask for a compressor")
    assert shared.made == before + 1
    for ws in browsers:
        assert ws.recv(timeout=60)  # the producers still send what each browser needs
        ws.close()
