"""Render the participant page's goal pictures: Table B with the objects in their slots, labelled.

Run as `python -m tableteach.sim.goal_picture [out_dir]` (default frontend/); renders offscreen with
MuJoCo (MUJOCO_GL=egl unless set) and labels the objects with matplotlib. The robot places the objects
itself, so the picture shows exactly what the labeling function calls "in its slot".
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

OUT_DIR = Path(__file__).resolve().parents[2] / "frontend"
SIZE = (480, 640)  # height, width
# (objects placed, objects marked optional, title) per task; the order is the order of placing.
GOALS = {
    "task1": (("dinner_plate", "small_plate", "bowl", "knife", "fork"), (), "Task 1: the table set for dinner"),
    "task2": (("dinner_plate", "bowl", "knife", "fork"), ("knife", "fork"), "Task 2: a light meal (no small plate)"),
}
# Where each arrow points, in metres from the object's centre (plates: a visible bit of the rim), and
# where its label goes, as a pixel offset from that point.
ARROW_TIPS = {"dinner_plate": (0.085, -0.04, 0.0), "small_plate": (0.06, 0.02, 0.01), "bowl": (0.0, 0.0, 0.03),
              "knife": (0.04, -0.02, 0.0), "fork": (0.04, -0.02, 0.0)}
LABEL_OFFSETS = {"dinner_plate": (-120, 110), "small_plate": (150, -115), "bowl": (0, -105), "knife": (40, 110),
                 "fork": (-60, 110)}


def _project(camera: object, point: np.ndarray, height: int, width: int) -> tuple[float, float]:
    """Pixel (x, y) of a world point in a MuJoCo render (camera from renderer.scene.camera[0])."""
    pos, forward, up = (np.asarray(v, dtype=float) for v in (camera.pos, camera.forward, camera.up))  # type: ignore[attr-defined]
    right = np.cross(forward, up)
    d = point - pos
    scale = camera.frustum_near / camera.frustum_top * (height / 2)  # type: ignore[attr-defined]
    depth = d @ forward
    return width / 2 + scale * (d @ right) / depth, height / 2 - scale * (d @ up) / depth


def render_goal(task: str, out: Path) -> Path:
    """Place the task's objects with the simulated robot, render Table B and label the objects."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mujoco

    from .physics import MujocoWorld

    objects, optional, title = GOALS[task]
    world = MujocoWorld(seed=0)
    for obj in objects:
        world.place(obj)
    missing = set(objects) - world.labels()
    if missing:
        raise RuntimeError(f"the robot did not set {sorted(missing)} in their slots: expected all of {objects}")
    height, width = SIZE
    renderer = mujoco.Renderer(world.model, height, width)
    camera = mujoco.MjvCamera()
    camera.lookat[:] = (0.45, -0.33, 0.40)
    camera.distance, camera.azimuth, camera.elevation = 0.72, 180.0, -62.0
    renderer.update_scene(world.data, camera)
    image = renderer.render()
    scene_camera = renderer.scene.camera[0]
    fig = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(image)
    ax.set_axis_off()
    for obj in objects:
        geoms = np.flatnonzero(world.model.geom_bodyid == world.layout.body[obj])
        tip = world.data.geom_xpos[geoms].mean(axis=0) + np.asarray(ARROW_TIPS[obj])
        x, y = _project(scene_camera, tip, height, width)
        dx, dy = LABEL_OFFSETS[obj]
        text = obj.replace("_", " ") + (" (optional)" if obj in optional else "")
        ax.annotate(text, (x, y), (x + dx, y + dy), ha="center", va="center", fontsize=15,
                    bbox={"boxstyle": "round,pad=0.3", "fc": "white", "ec": "#333", "alpha": 0.92},
                    arrowprops={"arrowstyle": "-|>", "color": "#222", "lw": 1.6})
    ax.text(width / 2, 22, title, ha="center", va="center", fontsize=16, weight="bold",
            bbox={"boxstyle": "round,pad=0.35", "fc": "white", "ec": "none", "alpha": 0.9})
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    renderer.close()
    world.close()
    return out


def main(out_dir: Path = OUT_DIR) -> None:
    """Write goal-task1.png and goal-task2.png."""
    for task in GOALS:
        print(f"wrote {render_goal(task, out_dir / f'goal-{task}.png')}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT_DIR)
