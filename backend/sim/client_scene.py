"""A browser's own scene of one table, without viser's scene handles.

viser's per-client scene API keeps a handle per node for as long as the browser is connected (a frame, geoms and a
label per moving body: about 40 nodes, their props and a copy of every mesh, some 130 KiB a view). Here the messages
that make a model's moving bodies and the caption are recorded once per model, through the same BodyMirror and
viser's own add_* code as the shared scene (SceneTemplate), and replayed to each browser with its own owner stamp:
the meshes are shared, and a browser's ClientScene keeps only what it last sent (its bodies' poses, the clickable
objects and the caption).
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Callable, Sequence
from typing import Any

import mujoco
import numpy as np
from viser import _messages as viser_messages

from .motion_message import motion_message
from .view import (CAPTION_NODE, POSE_EPSILON, BodyIndex, BodyMirror, add_caption, body_index, changed_poses,
                   moving_bodies, write_pose)
from .viser_private import RecordingScene

# What a scene handle's on_click(callback) publishes: a plain left click.
CLICKABLE = (viser_messages.DragBinding(button="left", modifier=None),)


# What BodyMirror and add_caption make a model's moving bodies from (names, kinematics at rest, geoms, meshes, the
# object list in the text data): models with equal values (copies of one scene file's) share one template.
_MADE_FROM = ("names", "text_data", "body_parentid", "body_weldid", "body_jntadr", "body_jntnum", "body_pos",
              "body_quat", "jnt_type", "jnt_pos", "jnt_axis", "qpos0", "geom_type", "geom_bodyid", "geom_group",
              "geom_size", "geom_pos", "geom_quat", "geom_rgba", "geom_matid", "geom_dataid", "mat_rgba",
              "mesh_vertadr", "mesh_vertnum", "mesh_faceadr", "mesh_facenum", "mesh_vert", "mesh_face")


def template_key(model: mujoco.MjModel) -> bytes:
    """A digest of what a model's template is made from (every table's world has its own copy of its scene's model)."""
    digest = hashlib.blake2b(digest_size=16)
    for field in _MADE_FROM:
        value = getattr(model, field)
        digest.update(field.encode())
        digest.update(value if isinstance(value, bytes) else np.ascontiguousarray(value).tobytes())
    return digest.digest()


class SceneTemplate:
    """The messages that make a model's moving bodies (rest pose) and the caption, made once per model; read only."""

    def __init__(self, model: mujoco.MjModel) -> None:
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        recorder = RecordingScene()
        mirror = BodyMirror(recorder, model, data, moving_bodies(model))
        add_caption(recorder)
        self.messages = tuple(recorder.messages)
        self.names = tuple(mirror.frames)  # the bodies, in their rows' order
        self.frames = tuple(mirror.frames[name].name for name in self.names)  # their frames' scene nodes
        self.rows = {name: row for row, name in enumerate(self.names)}
        self.rest = np.array([mirror.pose_of(name) for name in self.names], dtype=float).reshape(-1, 7)
        self.geoms = {body: tuple(handle.name for handle in handles) for body, handles in mirror.geoms.items()}
        self.body_of = {node: body for body, nodes in self.geoms.items() for node in nodes}
        self._index_cache: dict[tuple[str, ...], BodyIndex] = {}

    def index(self, bodies: Sequence[str]) -> BodyIndex:
        """Which of these bodies the template has, and their rows."""
        return body_index(self._index_cache, self.rows, bodies)


class ClientScene:
    """One browser's scene of one table: made from a template, then only changes are queued to it."""

    def __init__(self, template: SceneTemplate, queue: Callable[[Any], None]) -> None:
        self.template = template
        self._queue = queue
        self._last = template.rest.copy()  # the last pose asked for per body (the POSE_EPSILON test)
        self._shown = [[pose[:3], pose[3:]] for pose in template.rest.tolist()]  # per body: what the browser has
        self.caption = ""
        self.caption_visible = False
        self.clickable: frozenset[str] = frozenset()
        for message in template.messages:
            queue(copy.copy(message))  # the props (and their meshes) are the template's, never changed

    def set_poses(self, bodies: Sequence[str], poses: np.ndarray) -> int:
        """Push (x, y, z, qw, qx, qy, qz) per body of the scene, skipping unchanged ones; how many were sent."""
        changed = changed_poses(self._last, self.template.index(bodies), poses)
        for row, pose in changed:
            write_pose(self.template.frames[row], pose.tolist(), self._shown[row], self._queue)
            self._last[row] = pose
        return len(changed)

    def play(self, bodies: Sequence[str], times: np.ndarray, poses: np.ndarray) -> int:
        """Queue a motion for the browser to play on its own clock: poses (frames, bodies, 7) at times (seconds from
        its start); only bodies that move from what the browser has are sent. The browser ends on the last frame,
        so that is what this scene has from now on. How many bodies move."""
        given, rows = self.template.index(bodies)
        wanted = np.asarray(poses, dtype=float)[:, given]
        moving = np.flatnonzero(np.max(np.abs(wanted - self._last[rows]), axis=(0, 2), initial=0.0) >= POSE_EPSILON)
        if not len(moving):
            return 0
        moved = rows[moving]
        self._queue(motion_message(tuple(self.template.frames[row] for row in moved.tolist()), times,
                                   wanted[:, moving]))
        final = wanted[-1, moving]
        self._last[moved] = final
        for row, pose in zip(moved.tolist(), final.astype(np.float32).astype(float).tolist(), strict=True):
            self._shown[row] = [pose[:3], pose[3:]]  # as the browser has it (float32)
        return len(moving)

    def set_caption(self, text: str) -> None:
        """The one-line status above the tables (hidden while empty)."""
        if text != self.caption:
            self._queue(viser_messages.SceneNodeUpdateMessage(CAPTION_NODE, {"text": text}))
            self.caption = text
        if bool(text) != self.caption_visible:
            self._queue(viser_messages.SetSceneNodeVisibilityMessage(CAPTION_NODE, bool(text)))
            self.caption_visible = bool(text)

    def set_clickable(self, objects: frozenset[str]) -> None:
        """Exactly these bodies (of those the scene has) are outlined on hover and report clicks."""
        geoms = self.template.geoms
        changed = objects ^ self.clickable
        for body in (body for body in geoms if body in changed):
            bindings = CLICKABLE if body in objects else ()
            for node in geoms[body]:
                self._queue(viser_messages.SetSceneNodeClickBindingsMessage(node, bindings))
        self.clickable = frozenset(objects & geoms.keys())

    def clicked(self, node: str) -> str | None:
        """The clickable body a click on this node is for, or None."""
        body = self.template.body_of.get(node)
        return body if body in self.clickable else None
