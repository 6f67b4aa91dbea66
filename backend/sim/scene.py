"""Load a table scene's MJCF (the dinner table, or one generated from a study's objects: scene_mjcf.py) and read the
names, slots, grasps and arm geometry the robot relies on."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from .arm import ArmGeometry
from .world import OBJECTS

SCENE_XML = Path(__file__).resolve().parents[2] / "sim_assets" / "dinner_table" / "scene.xml"
ARM_JOINTS = ("base_yaw", "shoulder", "elbow", "wrist_pitch", "wrist_roll")
FINGER_JOINTS = ("finger_left", "finger_right")
OBJECTS_TEXT = "tableteach_objects"  # a generated scene's custom text: its object names, space-separated


@dataclass(frozen=True)
class Grasp:
    """Where the fingertips close on an object, in the object's frame."""

    pos: np.ndarray  # grip point (3,)
    yaw: float  # finger-closing direction, radians about the object's z axis
    half_width: float  # half the thickness the fingers close on


@dataclass(frozen=True)
class Slot:
    """An object's place on Table B."""

    pos: np.ndarray  # bottom centre of the object when placed (3,)
    yaw: float


@dataclass(frozen=True)
class Layout:
    """Indices and geometry of one scene, shared read-only by all worlds built from it."""

    objects: tuple[str, ...]
    body: dict[str, int]
    qpos_adr: dict[str, int]  # start of each object's free joint (pos 3, quat 4)
    dof_adr: dict[str, int]  # start of each object's free-joint velocity (lin 3, ang 3)
    weld: dict[str, int]  # inactive grasp weld per object
    grasp: dict[str, Grasp]
    slot: dict[str, Slot]
    bottom: dict[str, float]  # lowest point of each object above its origin
    arm: ArmGeometry
    arm_qpos: np.ndarray  # qpos indices of the five arm joints
    arm_ctrl: np.ndarray  # actuator indices driving them
    finger_ctrl: np.ndarray
    moving_bodies: tuple[int, ...]  # bodies that can move (arm links and objects)
    table_top: float


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _body_z_extent(model: mujoco.MjModel, body: int) -> tuple[float, float]:
    """Lowest and highest point of a body's geoms in its own frame (from their bounding boxes)."""
    lows, highs = [], []
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    for g in np.flatnonzero(model.geom_bodyid == body):
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        corners = (centre + signs * half) @ rot.reshape(3, 3).T + model.geom_pos[g]
        lows.append(corners[:, 2].min())
        highs.append(corners[:, 2].max())
    return float(min(lows)), float(max(highs))


def _arm_geometry(model: mujoco.MjModel) -> ArmGeometry:
    """Link lengths from body offsets: every link of the arm points along its parent's z axis."""
    pos = {name: model.body(name).pos for name in ("turret", "upper_arm", "forearm", "wrist", "hand")}
    for name, p in pos.items():
        if name != "turret" and not np.allclose(p[:2], 0.0):
            raise ValueError(f"arm link {name!r} is offset sideways by {p[:2]}: expected links along z")
    pedestal = model.body("pedestal").pos
    turret = pedestal + pos["turret"]
    return ArmGeometry(
        base_xy=(float(turret[0]), float(turret[1])),
        shoulder_z=float(turret[2] + pos["upper_arm"][2]),
        upper=float(pos["forearm"][2]),
        fore=float(pos["wrist"][2]),
        hand=float(pos["hand"][2] + model.site("grip").pos[2]),
    )


def scene_objects(model: mujoco.MjModel) -> tuple[str, ...]:
    """The scene's object names: those its custom text lists (a generated scene), else the dinner objects."""
    text = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, OBJECTS_TEXT)
    if text < 0:
        return OBJECTS
    start, size = int(model.text_adr[text]), int(model.text_size[text])
    return tuple(bytes(model.text_data[start : start + size]).rstrip(b"\0").decode().split())


def read_layout(model: mujoco.MjModel) -> Layout:
    """Read the conventions documented at the top of scene.xml; raise if the model breaks them."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    objects = scene_objects(model)
    missing = [o for o in objects if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, o) < 0]
    if missing:
        raise ValueError(f"scene lacks object bodies {missing}: expected one body per object in {objects}")
    body = {o: model.body(o).id for o in objects}
    grasp, slot, bottom = {}, {}, {}
    for o in objects:
        site = model.site(f"grasp_{o}")
        # The site's y axis is the finger-closing direction.
        yaw = _yaw(site.quat) + np.pi / 2
        grasp[o] = Grasp(pos=site.pos.copy(), yaw=yaw, half_width=float(site.size[0]))
        slot_site = model.site(f"slot_{o}").id
        slot[o] = Slot(pos=data.site_xpos[slot_site].copy(), yaw=_yaw(_mat_to_quat(data.site_xmat[slot_site])))
        bottom[o] = _body_z_extent(model, body[o])[0]
    return Layout(
        objects=objects,
        body=body,
        qpos_adr={o: int(model.joint(o).qposadr[0]) for o in objects},
        dof_adr={o: int(model.joint(o).dofadr[0]) for o in objects},
        weld={o: model.equality(f"grasp_{o}").id for o in objects},
        grasp=grasp,
        slot=slot,
        bottom=bottom,
        arm=_arm_geometry(model),
        arm_qpos=np.array([model.joint(j).qposadr[0] for j in ARM_JOINTS]),
        arm_ctrl=np.array([model.actuator(j).id for j in ARM_JOINTS]),
        finger_ctrl=np.array([model.actuator(j).id for j in FINGER_JOINTS]),
        moving_bodies=tuple(int(b) for b in np.flatnonzero(model.body_weldid != 0)),
        table_top=float(np.mean([s.pos[2] for s in slot.values()])),
    )


def _mat_to_quat(mat: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat)
    return quat


@lru_cache(maxsize=4)
def _load(path: str) -> tuple[mujoco.MjModel, Layout]:
    model = mujoco.MjModel.from_xml_path(path)
    return model, read_layout(model)


def scene_layout(path: Path | str = SCENE_XML) -> Layout:
    """The scene's layout (shared, read-only), without a copy of its model."""
    return _load(str(path))[1]


def load_scene(path: Path = SCENE_XML) -> tuple[mujoco.MjModel, Layout]:
    """A private copy of the scene's model (the grasp weld lives in it) and the shared layout."""
    model, layout = _load(str(path))
    return copy.deepcopy(model), layout
