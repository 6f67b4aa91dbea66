"""The .viser file written from a recording's arrays plays as the file viser's own serializer records while a
SceneView shows the recording pose by pose (the way the studio wrote it before): the same scene, the same
captions at the same times, and the same poses at every moment, to within the mirror's skip tolerance."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest

from tableteach.sim import viser_file
from tableteach.sim.motion_file import HOLD_SECONDS, Studio
from tableteach.sim.physics import MujocoWorld
from tableteach.sim.recording import Recording
from tableteach.sim.view import POSE_EPSILON, SceneView

POSES = ("SetPositionMessage", "SetOrientationMessage")


def viser_recorded(world: MujocoWorld, recording: Recording, captions: Sequence[tuple[float, str]],
                   speed: float) -> bytes:
    """The reference: viser's scene serializer recording a SceneView re-posed frame by frame."""
    view = SceneView(world.model, clickable=())
    try:
        view.set_caption("")
        view.set_poses(recording.bodies, recording.poses[0])
        serializer = view.server.get_scene_serializer()
        pending = sorted(captions)
        previous = float(recording.times[0])
        for t, poses in zip(recording.times, recording.poses, strict=True):
            serializer.insert_sleep(max(0.0, (float(t) - previous) / speed))
            previous = float(t)
            while pending and pending[0][0] <= t:
                view.set_caption(pending.pop(0)[1])
            view.set_poses(recording.bodies, poses)
        view.set_caption("")
        serializer.insert_sleep(HOLD_SECONDS)
        return serializer.serialize()
    finally:
        view.close()


def _resolved(value: Any, buffers: list[bytes]) -> Any:
    """A message value with its binary placeholders replaced by the bytes they point at."""
    if isinstance(value, dict):
        if "__binary_index" in value:
            return (value["dtype"], buffers[value["__binary_index"]])
        return {k: _resolved(v, buffers) for k, v in value.items()}
    if isinstance(value, list):
        return [_resolved(v, buffers) for v in value]
    return value


def _states(recording: viser_file.ViserFile) -> dict[float, dict[tuple[str, str, str], Any]]:
    """The scene the player shows after each playback time's messages: (node, message type, field) -> value."""
    state: dict[tuple[str, str, str], Any] = {}
    out: dict[float, dict[tuple[str, str, str], Any]] = {}
    for t, message in recording.messages:
        kind, name = message["type"], str(message.get("name", ""))
        if kind == "SceneNodeUpdateMessage":
            for field, value in message["updates"].items():
                state[(name, "props", field)] = value
        else:
            for field, value in message.items():
                if field not in ("type", "name", "owner"):
                    key = (name, kind, field)
                    if field == "props":  # a node made anew: its properties, then its later updates
                        for prop, v in _resolved(value, recording.buffers).items():
                            state[(name, "props", prop)] = v
                    else:
                        state[key] = _resolved(value, recording.buffers)
        out[round(t, 9)] = dict(state)
    return out


DEFAULT_POSE = {"position": [0.0, 0.0, 0.0], "wxyz": [1.0, 0.0, 0.0, 0.0]}  # a node's pose before any is set


def _assert_same_scene(ours: dict[Any, Any], theirs: dict[Any, Any], when: float) -> None:
    for key in ours.keys() | theirs.keys():
        if key[1] in POSES:
            mine, other = ours.get(key, DEFAULT_POSE[key[2]]), theirs.get(key, DEFAULT_POSE[key[2]])
            np.testing.assert_allclose(mine, other, atol=2 * POSE_EPSILON, err_msg=f"{key} at {when:.3f} s")
        else:
            assert ours.get(key) == theirs.get(key), f"{key} at {when:.3f} s"


@pytest.mark.parametrize("speed", [1.0, 1.7])
def test_the_written_file_plays_the_same_scene_poses_and_captions_as_viser_recording_it(speed: float) -> None:
    world = MujocoWorld(3)
    starts = []
    for obj in ("bowl", "knife"):
        starts.append(float(world.data.time))
        world.place(obj)
    recording = world.recording
    captions = [(t, f"The robot is placing object {i + 1}") for i, t in enumerate(starts)]
    studio = Studio(world.model)
    ours = viser_file.decode(studio.render(recording, captions, speed=speed))
    theirs = viser_file.decode(viser_recorded(world, recording, captions, speed))

    assert ours.duration == pytest.approx(theirs.duration, abs=1e-9)
    assert ours.version == theirs.version
    # the captions change at the same moments to the same texts
    def caption_changes(f: viser_file.ViserFile) -> list[tuple[float, str, Any]]:
        return [(round(t, 9), m["type"], m.get("updates", m.get("visible"))) for t, m in f.messages
                if m.get("name") == "/caption" and t > 0]
    assert caption_changes(ours) == caption_changes(theirs)
    # the bodies move at the same moments (the first frame's time included) ...
    def pose_times(f: viser_file.ViserFile) -> list[float]:
        return sorted({round(t, 9) for t, m in f.messages if m["type"] in POSES and t > 0})
    assert pose_times(ours) == pytest.approx(pose_times(theirs), abs=1e-9)
    # ... and at every moment the player shows the same scene
    our_states, their_states = _states(ours), _states(theirs)
    assert our_states.keys() == their_states.keys()
    for when in their_states:
        _assert_same_scene(our_states[when], their_states[when], when)
    world.close()


def test_a_file_round_trips_through_encode_and_decode() -> None:
    original = viser_file.ViserFile(12.5, [(0.0, viser_file.set_visible("/a", True)),
                                           (1.25, viser_file.set_position("/a", [1.0, 2.0, 3.0]))],
                                    [b"\x01\x02\x03", b"\x04" * 17])
    again = viser_file.decode(viser_file.encode(original))
    assert again == original
    with pytest.raises(ValueError, match="expected a .viser file"):
        viser_file.decode(b"\x00")
