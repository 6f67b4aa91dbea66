"""The process's one viser server (ViewHub): each browser gets its own table's scene by its one-time ticket (the
messages viser's scene handles would send, from one template per scene), a connection without a valid ticket sees
the empty tables only, clicks reach on_click only for the browser's clickable objects, leaving is reported and lets
the view's state go, and every browser's message producers share one compressor. The places that rely on viser's
private code (sim/viser_private.py) fail here if an upgrade changes it: the ticket in the connection's path, the
compressor the producers make, the producer itself, and the scene recorder."""

from __future__ import annotations

import copy
import gc
import hashlib
import inspect
import weakref
from collections.abc import Iterator
from typing import Any

import msgpack
import msgspec
import mujoco
import numpy as np
import pytest
import viser
import zstandard
from websockets.sync.client import ClientConnection, connect

from tableteach.sim.client_scene import ClientScene, SceneTemplate, template_key
from tableteach.sim.physics import MujocoWorld
from tableteach.sim.scene import load_scene
from tableteach.sim.view import BodyMirror, add_caption, moving_bodies
from tableteach.sim.view_hub import ViewHub
from tableteach.sim.viser_private import SharedCompressors
from tests.waiting import wait_until

CAMERA = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [2.0, 0.0, 1.5],
          "image_height": 600, "image_width": 800, "fov": 0.9, "near": 0.01, "far": 100.0,
          "look_at": [0.0, 0.0, 0.4], "up_direction": [0.0, 0.0, 1.0]}


@pytest.fixture
def hub() -> Iterator[tuple[ViewHub, list[str], list[str], list[tuple[str, str]]]]:
    """A hub whose tables all show the arm at rest with the bowl clickable; it records who joined, left and clicked."""
    model, _ = load_scene()
    joined: list[str] = []
    left: list[str] = []
    clicks: list[tuple[str, str]] = []

    def on_join(key: str) -> tuple[list[str], np.ndarray, str, frozenset[str], object] | None:
        joined.append(key)
        return [], np.zeros((0, 7)), f"table {key}", frozenset({"bowl"}), model

    view_hub = ViewHub(model, on_join=on_join, on_click=lambda key, obj: clicks.append((key, obj)),
                       on_leave=left.append)
    try:
        yield view_hub, joined, left, clicks
    finally:
        view_hub.close()


def _browser(hub: ViewHub, path: str) -> ClientConnection:
    """A connection as viser's browser client makes it (its protocol version, then a camera message)."""
    ws = connect(f"ws://127.0.0.1:{hub.port()}/{path}", subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
                 max_size=None, compression=None)
    ws.send(msgpack.packb(CAMERA))
    return ws


def test_each_browser_sees_its_own_table_by_ticket_and_leaving_is_reported(hub) -> None:
    view_hub, joined, left, _ = hub
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
    view_hub, _, _, _ = hub
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


def _messages(ws: ClientConnection) -> list[dict[str, Any]]:
    """The messages of one window as viser's browser client reads them (zstd-compressed msgpack, then raw buffers)."""
    frame = ws.recv(timeout=60)
    assert isinstance(frame, bytes)
    size, packed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + packed], max_output_size=size)
    return list(msgpack.unpackb(inner)["messages"])


def _click(ws: ClientConnection, node: str, owner: str, modifier: str | None = None) -> None:
    """A click as viser's browser client reports it."""
    ws.send(msgpack.packb({"type": "SceneNodeClickMessage", "name": node, "instance_index": None,
                           "ray_origin": [2.0, 0.0, 1.5], "ray_direction": [-1.0, 0.0, -0.5],
                           "screen_pos": [0.5, 0.5], "modifier": modifier, "owner": owner}))


def test_a_browser_is_sent_its_tables_scene_and_its_clicks_reach_on_click_only_for_clickable_objects(hub) -> None:
    view_hub, _, _, clicks = hub
    ws = _browser(view_hub, view_hub.ticket("7/0"))
    wait_until(lambda: view_hub.views() == 1, "the browser to join")
    owner = str(view_hub.clients("7/0")[0].client_id)
    created: dict[str, str] = {}
    while "/caption" not in created or "/bowl/g27" not in created:
        created |= {m["name"]: m["owner"] for m in _messages(ws) if "props" in m}  # the messages that make nodes
    assert {created[name] for name in ("/turret", "/hand/g20", "/bowl/g27", "/bowl/label", "/caption")} == {owner}
    _click(ws, "/hand/g20", owner)  # the arm: never clickable
    _click(ws, "/fork/g40", owner)  # not clickable at this table
    _click(ws, "/bowl/g27", owner, modifier="shift")
    _click(ws, "/bowl/g27", "")  # the shared scene's, not this browser's
    _click(ws, "/bowl/g27", owner)
    wait_until(lambda: clicks, "the click on the bowl to reach on_click")
    assert clicks == [("7/0", "bowl")]
    ws.close()


def test_a_closed_views_state_is_let_go(hub) -> None:
    view_hub, _, left, _ = hub
    ws = _browser(view_hub, view_hub.ticket("3/0"))
    wait_until(lambda: view_hub.views() == 1, "the browser to join")
    scene = weakref.ref(view_hub._views[next(iter(view_hub._views))].scene)
    client = weakref.ref(view_hub.clients("3/0")[0])
    ws.close()
    wait_until(lambda: left == ["3/0"] and view_hub.views() == 0, "the view to be gone")
    wait_until(lambda: gc.collect() >= 0 and scene() is None and client() is None,
               "the view's scene and viser's client handle to be let go")


def _encoded(messages: list[Any]) -> list[bytes]:
    return [msgspec.msgpack.encode(m.as_serializable_dict()) for m in messages]


def test_a_client_scene_queues_what_visers_scene_handles_queue() -> None:
    world = MujocoWorld(0)
    world.place("bowl")
    model, bodies, poses = world.model, world.bodies, world.body_poses()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        theirs: list[Any] = []
        server.scene._websock_interface.queue_message = theirs.append  # type: ignore[method-assign]
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        mirror = BodyMirror(server.scene, model, data, moving_bodies(model))
        caption = add_caption(server.scene)
        mirror.set_poses(bodies, poses)
        caption.text, caption.visible = "placing the bowl", True
        for obj in ("bowl", "fork"):
            for handle in mirror.geoms[obj]:
                handle.on_click(lambda _event: None)
        for handle in mirror.geoms["bowl"]:
            handle.remove_click_callback("all")
    finally:
        server.stop()

    ours: list[Any] = []

    def queue(message: Any) -> None:  # as the client's scene queues it: stamped with its owner
        message.owner = ""
        ours.append(message)

    scene = ClientScene(SceneTemplate(model), queue)
    assert scene.set_poses(bodies, poses) > 0
    scene.set_caption("placing the bowl")
    scene.set_clickable(frozenset({"bowl", "fork"}))
    scene.set_clickable(frozenset({"fork"}))
    assert len(ours) > 100
    assert _encoded(ours) == _encoded(theirs)
    assert scene.clicked("/fork/g40") == "fork" and scene.clicked("/bowl/g27") is None


def test_the_recording_scene_keeps_what_visers_scene_sends_for_every_primitive_a_geom_can_be() -> None:
    from tableteach.sim.viser_private import RecordingScene

    def add_all(scene: viser.SceneApi) -> None:
        scene.add_frame("/body", show_axes=False, position=(0.1, 0.2, 0.3), wxyz=(0.0, 1.0, 0.0, 0.0))
        scene.add_box("/body/box", color=(1, 2, 3), dimensions=(0.1, 0.2, 0.3), opacity=0.5)
        scene.add_icosphere("/body/sphere", radius=1.0, scale=(0.1, 0.2, 0.3), color=(4, 5, 6))
        scene.add_cylinder("/body/cylinder", radius=0.1, height=0.2, color=(7, 8, 9), position=(0.0, 0.0, 0.1))
        scene.add_mesh_simple("/body/mesh", np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], dtype=np.uint32),
                              color=(10, 11, 12), side="double")
        scene.add_label("/body/label", "bowl", position=(0.0, 0.0, 0.02), anchor="top-center", visible=False)

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        theirs: list[Any] = []
        server.scene._websock_interface.queue_message = theirs.append  # type: ignore[method-assign]
        add_all(server.scene)
    finally:
        server.stop()
    recorder = RecordingScene()
    add_all(recorder)
    assert len(theirs) > 12 and _encoded(recorder.messages) == _encoded(theirs)


def test_one_template_serves_every_copy_of_a_scenes_model() -> None:
    first, second = MujocoWorld(0).model, MujocoWorld(3).model
    assert first is not second and template_key(first) == template_key(second)
    recoloured = copy.deepcopy(first)
    recoloured.geom_rgba[-1] = (0.1, 0.2, 0.3, 1.0)
    assert template_key(recoloured) != template_key(first)
    template = SceneTemplate(first)
    assert set(template.names) == moving_bodies(first) and template.rest.shape == (len(template.names), 7)


# viser 1.1.1's _message_producer, which sim/viser_private.py's producer repeats except for letting a window go.
VISERS_PRODUCER_SHA256 = "8283328d06cfa014576888930c49a857a2d79892dc89f9694444895945018ea3"


def test_the_hubs_producer_is_visers_letting_sent_windows_go(hub) -> None:
    from viser.infra import _infra

    from tableteach.sim import viser_private

    source = inspect.getsource(viser_private.VISERS_PRODUCER)
    assert hashlib.sha256(source.encode()).hexdigest() == VISERS_PRODUCER_SHA256, (
        "viser's _message_producer changed: compare it with sim/viser_private.py's and update both")
    view_hub, _, _, _ = hub
    view_hub.port()
    assert _infra._message_producer is viser_private._message_producer
