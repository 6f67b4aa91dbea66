"""A robot execution recorded as a .viser file that viser's own browser client plays back (`?playbackPath=`),
so watching the robot costs the server one file per execution instead of 30 pushed messages a second.

The file holds what viser's scene serializer would record while a SceneView replayed the recording pose by
pose: the scene as it stands, then at each frame's time the pose messages of the bodies that moved (more than
POSE_EPSILON, and only the parts viser itself would resend) and the caption changes. A hidden SceneView is
made once per process for the scene's snapshot (ViserServer.get_scene_serializer); the frames are written
from the recording's arrays (tableteach.sim.viser_file), which costs a few hundredths of what driving viser's
scene through every pose did.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from . import viser_file
from .recording import Recording
from ..recording_store import VISER_SUFFIX, FileRecordingStore, RecordingId
from .view import CAPTION_NODE, POSE_EPSILON, SceneView
from .viser_file import Encoded, Timed, ViserFile

SUFFIX = VISER_SUFFIX
# viser's player starts a recording again once it reaches its end; holding the last pose this long keeps a
# finished execution still on screen (the participant judges it) instead of replaying it by itself.
HOLD_SECONDS = 600.0
# viser resends a position or orientation only if it is not numpy.allclose to the one sent before.
_RTOL, _ATOL = 1e-5, 1e-8
_POSE_TYPES = ("SetPositionMessage", "SetOrientationMessage")


def viser_path(data_dir: Path | str, rid: RecordingId) -> Path:
    """Where the .viser file of a recorded step is kept (next to its .npz and .json)."""
    return FileRecordingStore(data_dir).playable(rid)


class SceneSnapshot:
    """The scene's messages as viser's serializer starts a file (caption empty and hidden), and its frames."""

    def __init__(self, messages: list[Timed], buffers: list[bytes]) -> None:
        self.messages = messages
        self.buffers = buffers
        self.frames = frozenset(m["name"] for _t, m in messages if m["type"] == "FrameMessage")  # "/<body>"
        self._without: dict[frozenset[str], Encoded] = {}

    def without_poses_of(self, names: frozenset[str]) -> Encoded:
        """The snapshot's messages except the poses of these nodes, encoded (kept for the next recording)."""
        cached = self._without.get(names)
        if cached is None:
            kept = [(t, m) for t, m in self.messages if not (m["type"] in _POSE_TYPES and m["name"] in names)]
            cached = self._without[names] = viser_file.encode_messages(kept)
        return cached


def scene_snapshot(model: mujoco.MjModel) -> SceneSnapshot:
    """The start of every recording of this scene, taken from a SceneView made and closed for it."""
    view = SceneView(model, clickable=())
    try:
        view.set_caption("")
        start = viser_file.decode(view.server.get_scene_serializer().serialize())
    finally:
        view.close()
    return SceneSnapshot([item for item in start.messages if not isinstance(item, Encoded)], start.buffers)


def _sends(poses: np.ndarray) -> np.ndarray:
    """[frame, body, 0 or 1]: whether a SceneView showing the frames in turn sends the body's position (0) or
    orientation (1) then. The mirror skips a body that moved less than POSE_EPSILON since it last sent it, and
    viser skips a value numpy.allclose to the one it holds. Every body starts at its first pose."""
    frames, bodies = poses.shape[:2]
    sends = np.zeros((frames, bodies, 2), dtype=bool)
    sent = poses[0].copy()  # the mirror's last sent pose
    held = poses[0].copy()  # viser's position and orientation
    for f in range(1, frames):
        pose = poses[f]
        moved = (np.abs(pose - sent) >= POSE_EPSILON).any(axis=1)
        if not moved.any():
            continue
        sent[moved] = pose[moved]
        changed = np.abs(pose - held) > _ATOL + _RTOL * np.abs(held)
        send = sends[f]
        send[:, 0] = moved & changed[:, :3].any(axis=1)
        send[:, 1] = moved & changed[:, 3:].any(axis=1)
        held[send[:, 0], :3] = pose[send[:, 0], :3]
        held[send[:, 1], 3:] = pose[send[:, 1], 3:]
    return sends


def motion(scene: SceneSnapshot, recording: Recording, captions: Sequence[tuple[float, str]] = (),
           speed: float = 1.0) -> ViserFile:
    """The .viser recording of `recording` played at `speed`, captions being (recording time, text) shown from then.

    Message for message what viser's serializer records when a SceneView shows each frame in turn after a sleep
    of the frame's interval / speed, except that the scene starts with every body explicitly at its first pose.
    """
    if speed <= 0:
        raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.0")
    if len(recording) == 0:
        raise ValueError("the recording has no frames: expected at least one pose")
    keep = [i for i, b in enumerate(recording.bodies) if f"/{b}" in scene.frames]
    names = [f"/{recording.bodies[i]}" for i in keep]
    poses = np.ascontiguousarray(recording.poses[:, keep], dtype=float)
    messages: list[Timed | Encoded] = [scene.without_poses_of(frozenset(names))]
    for name, pose in zip(names, poses[0].tolist(), strict=True):
        messages += [(0.0, viser_file.set_position(name, pose[:3])), (0.0, viser_file.set_orientation(name, pose[3:]))]

    # Playback times: viser's serializer adds each frame's sleep to its clock, in this order.
    times = [float(t) for t in recording.times]
    clocks, clock, previous = [], 0.0, times[0]
    for t in times:
        clock += max(0.0, (t - previous) / speed)
        previous = t
        clocks.append(clock)
    frame, node, part = np.nonzero(_sends(poses))  # frame by frame, body by body, position first
    values = poses[frame, node][np.arange(len(frame))[:, None], (3 * part)[:, None] + np.arange(4)]
    clock_of = np.asarray(clocks)

    caption = ["", False]  # the snapshot's caption text and visibility

    def show(at: float, text: str) -> None:
        if text != caption[0]:
            messages.append((at, viser_file.set_text(CAPTION_NODE, text)))
            caption[0] = text
        if bool(text) != caption[1]:
            messages.append((at, viser_file.set_visible(CAPTION_NODE, bool(text))))
            caption[1] = bool(text)

    def poses_before(end: int) -> None:
        rows = slice(done[0], end)
        messages.append(viser_file.pose_messages(names, clock_of[frame[rows]], node[rows], part[rows] == 0,
                                                 values[rows]))
        done[0] = end

    done = [0]
    recording_times = np.asarray(times)
    for at, text in sorted(captions):
        # a caption is shown at the first frame at or after its time, before that frame's poses
        f = int(np.searchsorted(recording_times, at, side="left"))
        if f >= len(times):
            break
        poses_before(int(np.searchsorted(frame, f, side="left")))
        show(clocks[f], text)
    poses_before(len(frame))
    show(clock, "")
    return ViserFile(clock + HOLD_SECONDS, messages, scene.buffers)


class Studio:
    """Turns recordings into .viser files of one scene; thread-safe."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self._model = model
        self._scene: SceneSnapshot | None = None
        self._lock = threading.Lock()

    def scene(self) -> SceneSnapshot:
        """The scene's snapshot, taken on first use."""
        with self._lock:
            if self._scene is None:
                self._scene = scene_snapshot(self._model)
            return self._scene

    def render(self, recording: Recording, captions: Sequence[tuple[float, str]] = (), *, speed: float = 1.0) -> bytes:
        """The .viser bytes of a recording played at `speed`; captions are (recording time, text) to show from then."""
        return viser_file.encode(motion(self.scene(), recording, captions, speed))

    def close(self) -> None:
        """Forget the snapshot (no viser server is left running)."""
        with self._lock:
            self._scene = None

