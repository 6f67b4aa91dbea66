"""The participant page's 2D view: the tables from above and the current step's recorded motion, made compact.

Reads only (no database write, no robot call): the scene's layout and the recording the 3D view plays, both
through the recording store; each frame keeps x, y, z (metres, to the millimetre) and yaw (radians)."""

from __future__ import annotations

import math
from typing import Any

from .context import Context
from .state import participant_and_study
from .study_objects import study_scene
from .viewing import current_motion


def _yaw(w: float, x: float, y: float, z: float) -> float:
    """Rotation about the vertical axis of a unit quaternion (w, x, y, z)."""
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def compact_motion(recording: dict[str, Any]) -> dict[str, Any]:
    """A top view's poses (x, y, z, qw, qx, qy, qz per body) as [x, y, z, yaw], to 1 mm and 0.001 rad."""
    frames = [[[round(p[0], 3), round(p[1], 3), round(p[2], 3), round(_yaw(*p[3:7]), 3)] for p in frame]
              for frame in recording["poses"]]
    return {"bodies": list(recording["bodies"]), "times": list(recording["times"]), "poses": frames,
            "action_ends": list(recording.get("action_ends", []))}


def flat_view(ctx: Context, token: str) -> dict[str, Any]:
    """The tables, robot base and objects from above, and the current step's recorded motion (None when the step
    has none: a demonstration, or an execution not worked out yet, `pending` then being true)."""
    with ctx.db.read() as s:
        _participant, study = participant_and_study(s, token)  # an unknown token is refused before the scene is loaded
        scene = study_scene(study)
    motion = current_motion(ctx, token)
    recorded = None if motion is None else ctx.store.top_view(motion.recording, scene)
    step = None if motion is None else {"task_index": motion.recording.task_index,
                                        "kind": motion.recording.step_kind, "index": motion.recording.step_index}
    return {"layout": ctx.store.layout(scene), "step": step, "replays": 0 if motion is None else motion.replays,
            "pending": motion is not None and recorded is None,
            "motion": None if recorded is None else compact_motion(recorded)}
