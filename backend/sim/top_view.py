"""A table scene (the dinner table, or one with a study's own objects) seen from above, for the dashboard's replays
and the participant's 2D view: the tables, the robot's base, each object's footprint, start and slot, and a recorded
step's poses thinned to REPLAY_FPS. Reached by the services through the recording store
(tableteach.recording_store.RecordingStore.layout / top_view), never imported by them."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Any

from ..recording_store import FileRecordingStore, RecordingId
from ..scenes.spec import SceneSpec

def _quat_yaw(w: float, x: float, y: float, z: float) -> float:
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


@lru_cache(maxsize=16)
def table_layout(scene: str | None = None) -> dict[str, Any]:
    """The scene seen from above (metres, world frame): both tables, the robot's base, each object's size and poses
    (the dinner scene when `scene` is None)."""
    from .scene import SCENE_XML, load_scene  # imports MuJoCo: only replays need it

    model, layout = load_scene(SCENE_XML if scene is None else Path(scene))
    tables = []
    for name, geom in (("Table A", "table_a_top"), ("Table B", "table_b_top")):
        g = model.geom(geom)
        centre = model.body(int(g.bodyid[0])).pos + g.pos
        tables.append({"name": name, "x": float(centre[0]), "y": float(centre[1]),
                       "half_x": float(g.size[0]), "half_y": float(g.size[1])})
    pedestal = model.geom("pedestal")
    objects = {}
    for obj in layout.objects:
        body = model.body(obj)
        half_x, half_y = _footprint(model, layout.body[obj])
        objects[obj] = {
            "shape": "disc" if abs(half_x - half_y) < 0.01 else "bar",
            "half_x": half_x, "half_y": half_y,
            "start": {"x": float(body.pos[0]), "y": float(body.pos[1]), "yaw": _quat_yaw(*map(float, body.quat))},
            "slot": {"x": float(layout.slot[obj].pos[0]), "y": float(layout.slot[obj].pos[1]),
                     "yaw": layout.slot[obj].yaw},
        }
    return {"tables": tables, "robot": {"x": 0.0, "y": 0.0, "radius": float(pedestal.size[0])}, "objects": objects}


def _footprint(model: Any, body: int) -> tuple[float, float]:
    """Half extents in x and y of a body's drawn geoms, in the body's frame (from their rotated bounding boxes)."""
    xs, ys = [0.0], [0.0]
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body or model.geom_group[g] == 3:  # group 3: collision only, not drawn
            continue
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        rot = _quat_matrix(*map(float, model.geom_quat[g]))
        for sx in (-1, 1):
            for sy in (-1, 1):
                for sz in (-1, 1):
                    corner = [centre[0] + sx * half[0], centre[1] + sy * half[1], centre[2] + sz * half[2]]
                    xs.append(abs(model.geom_pos[g][0] + sum(rot[0][k] * corner[k] for k in range(3))))
                    ys.append(abs(model.geom_pos[g][1] + sum(rot[1][k] * corner[k] for k in range(3))))
    return max(xs), max(ys)


def _quat_matrix(w: float, x: float, y: float, z: float) -> list[list[float]]:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


REPLAY_FPS = 15.0
ARM_BODIES = ("forearm", "hand")  # the elbow and the hand: enough to draw the arm from above


def _recording_view(saved: Any, objects: tuple[str, ...]) -> dict[str, Any]:
    """The objects' and arm's poses at no more than REPLAY_FPS, rounded to 0.1 mm (JSON stays small)."""
    rec = saved.recording
    keep = [i for i, b in enumerate(rec.bodies) if b in objects or b in ARM_BODIES]
    times = rec.times
    stride = 1
    if len(times) > 1 and rec.duration > 0:
        stride = max(1, round((len(times) - 1) / rec.duration / REPLAY_FPS))
    frames = list(range(0, len(times), stride))
    if frames and frames[-1] != len(times) - 1:
        frames.append(len(times) - 1)  # always end on the final state
    return {
        "bodies": [rec.bodies[i] for i in keep],
        "times": [round(float(times[f]), 4) for f in frames],
        "poses": [[[round(float(v), 4) for v in rec.poses[f, i]] for i in keep] for f in frames],
        "action_ends": list(saved.action_ends),
    }




def own_objects_layout(spec: SceneSpec, data_dir: Path | str) -> dict[str, Any]:
    """The top view of a scene generated from a study's objects, each object with its shape and colour as specified
    ("shape" keeps the dinner layout's meaning: a disc or a bar from above)."""
    from .clips import CACHE_FOLDER
    from .scene_mjcf import SCENE_FOLDER, scene_path

    base = table_layout(str(scene_path(spec, Path(data_dir) / CACHE_FOLDER / SCENE_FOLDER)))
    objects = {o.name: {**base["objects"][o.name], "kind": o.shape, "colour": o.colour} for o in spec.objects}
    return {**base, "objects": objects}


class SceneRecordingStore(FileRecordingStore):
    """The file recording store with the scene's top view (the composition root's store for the services)."""

    def layout(self, scene: SceneSpec | None = None) -> dict[str, Any]:
        """The scene from above (see table_layout): the dinner table's, or that of a study's own objects."""
        return table_layout() if scene is None else own_objects_layout(scene, self.data_dir)

    def top_view(self, rid: RecordingId, scene: SceneSpec | None = None) -> dict[str, Any] | None:
        """A recorded step's objects and arm from above, or None if the robot saved no recording of it."""
        from .recordings import load_recording  # numpy only

        try:
            saved = load_recording(self.data_dir, rid)
        except FileNotFoundError:
            return None
        return _recording_view(saved, tuple(self.layout(scene)["objects"]))


def scene_store(data_dir: Path | str) -> SceneRecordingStore:
    """The recording store of a data folder, with the scene's top view."""
    return SceneRecordingStore(data_dir)
