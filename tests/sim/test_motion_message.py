"""A placement's motion sent once to each browser (sim/motion_message.py): the client scene sends exactly the bodies
that move, as float32 frames the page plays, and from then on holds the motion's last frame; a browser connected to
the hub receives the motion as one message stamped with its owner and no pose frames; the robot's animator sends a
watched placement once, ends it no sooner than its length at the table's speed, and shows its last frame."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tableteach.sim.client_scene import ClientScene, SceneTemplate
from tableteach.sim.motion_message import MESSAGE_TYPE, TableTeachMotionMessage, motion_message
from tableteach.sim.physics import MujocoWorld
from tableteach.sim.robot import MujocoRobot
from tests.sim.test_view_hub import _browser, _messages, hub  # noqa: F401  (hub is a fixture used by name)
from tests.waiting import wait_until


def _placement() -> tuple[MujocoWorld, Any]:
    """A world that has placed the bowl, and that placement's frames."""
    world = MujocoWorld(0)
    start = len(world.recording) - 1
    world.place("bowl")
    return world, world.recording.since(start)


def _decoded(message: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """A motion message's times and poses, as the page reads them."""
    times = np.frombuffer(message["times"], dtype="<f4")
    return times, np.frombuffer(message["poses"], dtype="<f4").reshape(len(times), len(message["nodes"]), 7)


def test_a_client_scene_sends_the_bodies_that_move_once_and_then_holds_the_last_frame() -> None:
    world, segment = _placement()
    template = SceneTemplate(world.model)
    sent: list[Any] = []
    scene = ClientScene(template, sent.append)
    scene.set_poses(segment.bodies, segment.poses[0])  # the browser shows the table as it was
    sent.clear()
    times = (segment.times - segment.times[0]) / 2.0
    assert scene.play(segment.bodies, times, segment.poses) > 1  # the arm's links and the bowl
    (message,) = sent
    assert isinstance(message, TableTeachMotionMessage)
    wire = message.as_serializable_dict()
    got_times, got_poses = _decoded(wire)
    assert wire["type"] == MESSAGE_TYPE and len(got_times) == len(segment)
    np.testing.assert_allclose(got_times, times, atol=1e-5)
    # every body whose pose changes is there, under its scene node's name, and no body that stays put
    body_of = dict(zip(template.frames, template.names, strict=True))
    sent_bodies = [body_of[node] for node in wire["nodes"]]
    np.testing.assert_allclose(got_poses, segment.poses[:, [segment.bodies.index(b) for b in sent_bodies]], atol=1e-5)
    for body in set(template.names) - set(sent_bodies):
        k = segment.bodies.index(body)
        assert np.abs(segment.poses[:, k] - segment.poses[0, k]).max() < 1e-4
    assert "/bowl" in wire["nodes"] and "/fork" not in wire["nodes"]

    sent.clear()
    assert scene.set_poses(segment.bodies, segment.poses[-1]) == 0 and sent == []  # the browser ends there
    assert scene.play(segment.bodies, times[-1:], segment.poses[-1:]) == 0 and sent == []  # nothing moves
    assert scene.set_poses(segment.bodies, segment.poses[0]) == len(wire["nodes"])  # back: each moved body again


def test_a_motion_message_checks_its_shape() -> None:
    with pytest.raises(ValueError, match=r"expected \(3, 2, 7\) for 3 times and 2 nodes"):
        motion_message(("/a", "/b"), np.zeros(3), np.zeros((3, 1, 7)))


def test_a_browser_receives_a_played_motion_as_one_message_with_its_owner(hub: Any) -> None:  # noqa: F811
    view_hub = hub[0]
    world, segment = _placement()
    ws = _browser(view_hub, view_hub.ticket("5/0"))
    wait_until(lambda: view_hub.views() == 1, "the browser to join")
    owner = str(view_hub.clients("5/0")[0].client_id)
    while not any(m.get("name") == "/caption" for m in _messages(ws)):  # the scene, sent first
        pass
    assert view_hub.play("5/0", segment.bodies, segment.times - segment.times[0], segment.poses) == 1
    got: list[dict[str, Any]] = []
    while not any(m["type"] == MESSAGE_TYPE for m in got):
        got += _messages(ws)
    (motion,) = [m for m in got if m["type"] == MESSAGE_TYPE]
    assert motion["owner"] == owner and len(_decoded(motion)[0]) == len(segment)
    assert not [m for m in got if m["type"] in ("SetPositionMessage", "SetOrientationMessage")]
    ws.close()


class RecordingHub:
    """Stands in for the robot's view hub: one browser watching every table; records what it is asked to do."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, float, Any]] = []
        self.lock = threading.Lock()

    def watchers(self, key: str) -> int:
        return 1

    def play(self, key: str, bodies: Any, times: np.ndarray, poses: np.ndarray) -> int:
        with self.lock:
            self.calls.append(("play", time.monotonic(), (times, poses)))
        return 1

    def show(self, key: str, bodies: Any, poses: np.ndarray) -> int:
        with self.lock:
            self.calls.append(("show", time.monotonic(), poses))
        return 1

    def set_caption(self, key: str, text: str) -> None:
        with self.lock:
            self.calls.append(("caption", time.monotonic(), text))

    def set_clickable(self, key: str, objects: frozenset[str]) -> None:
        pass

    def close(self) -> None:
        pass


def test_the_animator_sends_a_watched_placement_once_and_ends_it_after_its_length(tmp_path: Path) -> None:
    robot = MujocoRobot(data_dir=tmp_path, speed=4.0)
    fake = RecordingHub()
    robot._hub = fake  # type: ignore[assignment]
    robot.start()
    try:
        robot.set_speed("1/0", 2.0)
        robot.reset("1/0")
        robot.place("1/0", "bowl")
        wait_until(lambda: not robot.activity("1/0").moving, "the placement to end", timeout=120)  # type: ignore[union-attr]
    finally:
        robot.shutdown()
    kinds = [c[0] for c in fake.calls]
    plays = [c for c in fake.calls if c[0] == "play"]
    assert len(plays) == 1 and kinds.count("show") == 2  # the reset's still table, then the motion's last frame
    (_, started, (times, poses)) = plays[0]
    assert times[0] == 0.0 and len(times) == len(poses) > 30
    ended = [c for c in fake.calls if c[0] == "show"][-1]
    np.testing.assert_array_equal(ended[2], poses[-1])
    # the motion's length at 8x (the robot's 4x and the table's 2x) is what the page plays, and it ends no sooner
    segment_seconds = float(times[-1]) * 8.0
    assert segment_seconds > 2.0 and ended[1] - started >= times[-1] - 1e-3
    captions = [c[2] for c in fake.calls if c[0] == "caption"]
    assert captions[-2:] == ["The robot is placing the bowl", ""]
