"""The viser view: one server per participant on 127.0.0.1, clickable objects, pose pushes, playback."""

import socket
import threading
import time

import numpy as np
import pytest

from tableteach.sim import OBJECTS
from tableteach.sim.physics import MujocoWorld
from tableteach.sim.playback import play
from tableteach.sim.view import SceneView, capsule_mesh


@pytest.fixture(scope="module")
def world():
    w = MujocoWorld(seed=0)
    w.place("bowl")
    return w


def _port_is_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
        return True


def test_server_binds_localhost_and_releases_port_and_threads(world):
    threads_before = set(threading.enumerate())
    view = SceneView(world.model)
    port = view.port
    assert port > 0 and not _port_is_free(port)
    assert view.server.get_host() == "127.0.0.1"
    view.close()
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and (set(threading.enumerate()) - threads_before):
        time.sleep(0.05)
    assert set(threading.enumerate()) - threads_before == set()
    assert _port_is_free(port)


def test_two_views_get_different_ports(world):
    first, second = SceneView(world.model), SceneView(world.model)
    try:
        assert first.port != second.port
    finally:
        first.close()
        second.close()


@pytest.fixture
def view(world):
    v = SceneView(world.model, on_click=lambda name: None)
    yield v
    v.close()


def test_objects_start_clickable_and_can_be_disabled(view):
    assert view.clickable == frozenset(OBJECTS)
    view.set_clickable("bowl", False)
    assert view.clickable == frozenset(OBJECTS) - {"bowl"}
    with pytest.raises(ValueError, match="unknown object 'spoon'"):
        view.set_clickable("spoon", True)


def test_only_changed_bodies_are_pushed(view, world):
    rec = world.recording
    moving = view.set_poses(rec.bodies, rec.poses[len(rec) // 2])
    assert 0 < moving <= len(rec.bodies)
    assert view.set_poses(rec.bodies, rec.poses[len(rec) // 2]) == 0


def test_playback_follows_recorded_time_and_stops_on_request(view, world):
    rec = world.recording
    started = time.perf_counter()
    assert play(rec, view, speed=5.0) >= 1
    # Never ahead of the recorded time (a busy machine only makes it later, with frames skipped).
    assert time.perf_counter() - started >= rec.duration / 5 * 0.95
    stop = threading.Event()
    stop.set()
    assert play(rec, view, stop=stop) == 0
    np.testing.assert_allclose(view._mirror.pose_of("bowl"), rec.poses[-1, rec.bodies.index("bowl")], atol=1e-4)


def test_late_playback_skips_frames_instead_of_slowing_down(view, world):
    rec = world.recording
    shown = play(rec, view, speed=1000.0)  # far faster than poses can be pushed
    assert shown < len(rec) / 2  # slow motion would have shown every frame
    np.testing.assert_allclose(view._mirror.pose_of("hand"), rec.poses[-1, rec.bodies.index("hand")], atol=1e-4)


def test_capsule_mesh_is_closed_and_sized():
    vertices, faces = capsule_mesh(0.04, 0.2)
    assert np.isclose(vertices[:, 2].max(), 0.24) and np.isclose(vertices[:, 2].min(), -0.24)
    assert np.isclose(np.hypot(vertices[:, 0], vertices[:, 1]).max(), 0.04)
    assert faces.max() < len(vertices)


def test_each_object_carries_its_name_as_a_label_in_recordings_too(world):
    from tableteach.sim import viser_file

    view = SceneView(world.model, clickable=())
    try:
        recorded = viser_file.decode(view.server.get_scene_serializer().serialize())
    finally:
        view.close()
    labels = {m["name"]: m["props"]["text"] for _t, m in recorded.messages if m["type"] == "LabelMessage"}
    for obj in OBJECTS:  # a child of the object's frame: it moves with the object
        assert labels[f"/{obj}/label"] == obj.replace("_", " ")


def _pushed_messages(world, fast: bool) -> list[tuple[str, str, tuple[float, ...], str]]:
    """The pose messages a mirror queues for a stretch of the recording, by the fast writer or viser's setters."""
    import mujoco
    import viser

    from tableteach.sim.view import BodyMirror

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        data = mujoco.MjData(world.model)
        mujoco.mj_forward(world.model, data)
        mirror = BodyMirror(server.scene, world.model, data)
        assert all(w is not None for w in mirror._writers), "viser no longer has what the fast pose writer needs"
        if not fast:
            mirror._writers = [None] * len(mirror._writers)
        queued: list = []
        server.scene._websock_interface.queue_message = queued.append  # type: ignore[method-assign]
        rec = world.recording
        for frame in range(0, len(rec), 7):
            mirror.set_poses(rec.bodies, rec.poses[frame])
        return [(type(m).__name__, m.name, tuple(m.position if hasattr(m, "position") else m.wxyz), m.owner)
                for m in queued]
    finally:
        server.stop()


def test_the_fast_pose_writer_queues_what_viser_setters_queue(world):
    fast, public = _pushed_messages(world, True), _pushed_messages(world, False)
    assert len(fast) > 20
    assert [m[:2] + (m[3],) for m in fast] == [m[:2] + (m[3],) for m in public]
    for ours, theirs in zip(fast, public, strict=True):
        np.testing.assert_allclose(ours[2], theirs[2], atol=1e-12)
