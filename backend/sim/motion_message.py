"""A placement's motion sent to a browser once, for the viewer page to play (frontend/viewer-motion.js), instead of
30 frames a second of pose messages from the server.

The message travels in viser's websocket like any other scene message, stamped with the browser's owner. The viewer
page takes it out of each batch before viser's client sees it and, frame by frame on its own clock, hands viser the
same SetPositionMessage/SetOrientationMessage the server used to stream (node names, owner, values). Poses and
times are float32 bytes (msgpack bin): a 5.5 s placement of 10 moving bodies is about 46 KB before compression.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from viser import _messages as viser_messages

MESSAGE_TYPE = "TableTeachMotionMessage"


@dataclasses.dataclass
class TableTeachMotionMessage(viser_messages.Message, include_in_scene_serialization=False):
    """Play this motion now: `poses` holds float32 (frames, nodes, 7) = x, y, z, qw, qx, qy, qz per node, shown at
    `times` (float32 seconds from the motion's start, at the speed it is to be played)."""

    nodes: tuple[str, ...]
    times: bytes
    poses: bytes
    owner: str = dataclasses.field(default="", init=False)

    def redundancy_key(self) -> str:
        """One motion at a time per browser: a newer one not yet sent replaces an older one."""
        return MESSAGE_TYPE

    def as_serializable_dict(self, binary_buffers: list[memoryview] | None = None) -> dict[str, Any]:
        """What the viewer page reads: node names, times and poses as little-endian float32 bytes."""
        return {"type": MESSAGE_TYPE, "nodes": list(self.nodes), "times": self.times, "poses": self.poses,
                "owner": self.owner}


def motion_message(nodes: tuple[str, ...], times: np.ndarray, poses: np.ndarray) -> TableTeachMotionMessage:
    """The message for poses (frames, len(nodes), 7) at times (frames,) seconds from the start."""
    f = len(times)
    if poses.shape != (f, len(nodes), 7):
        raise ValueError(f"poses have shape {poses.shape}: expected ({f}, {len(nodes)}, 7) for {f} times and "
                         f"{len(nodes)} nodes")
    return TableTeachMotionMessage(nodes, np.ascontiguousarray(times, dtype="<f4").tobytes(),
                                   np.ascontiguousarray(poses, dtype="<f4").tobytes())
