"""The MuJoCo table world: the arm picks each object from Table A and sets it in its slot on Table B.

Each world owns a private model copy, because the grasp weld's relative pose lives in the model
(model.eq_data). Motion is closed-form IK (tableteach.sim.arm) tracked by position servos; a
grasp activates the object's weld. Labels are read from the physical state, never from the command.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from . import arm
from .recording import Recording
from .scene import SCENE_XML, load_scene
from .world import MoveLog

CONTROL_DT = 1 / 30  # seconds per servo set-point: one mj_step call (GIL released) per frame
FRAME_DT = 1 / 30  # seconds between recorded frames
HOVER = 0.12  # approach height above a grasp or place point
CLEARANCE = 0.004  # gap left under an object when it is released
SLOT_TOLERANCE = 0.025  # metres an object's centre may be off its slot and still count as placed
STACK_HEIGHT = 0.12  # how far above the table top a stacked object may rest
REST_SPEED = 0.05  # m/s below which an object counts as at rest
FINGER_OPEN = 0.04
DROP_XY = (-0.3, 0.25)  # over the floor behind the robot, clear of both tables
JITTER_XY, JITTER_YAW = 0.008, 0.06  # seeded perturbation of the start poses on Table A
STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # everything mj_step reads (time, qpos, qvel, ctrl, warmstart, ...)


@dataclass(frozen=True)
class Clip:
    """One placement as the world simulated it: the frames it recorded, the labels after it, and what puts a
    world at its end again: the integration state before its last control tick (replaying that one tick
    rebuilds every derived quantity exactly), the grasp welds' parameters and the frame clock."""

    obj: str
    times: np.ndarray  # (n,) the frames recorded during the placement
    poses: np.ndarray  # (n, B, 7)
    labels: frozenset[str]
    before_last_tick: np.ndarray
    eq_data: np.ndarray
    next_frame: float

    @property
    def nbytes(self) -> int:
        """Memory the clip holds (its arrays)."""
        return self.times.nbytes + self.poses.nbytes + self.before_last_tick.nbytes + self.eq_data.nbytes


def _min_jerk(n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n + 1)[1:]
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def _rot_z(yaw: float, v: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])


class MujocoWorld(MoveLog):
    """TableWorld backed by MuJoCo physics; not thread-safe (one caller at a time)."""

    _held: str | None  # the object in the hand

    def __init__(self, seed: int = 0, scene: Path = SCENE_XML) -> None:
        self.scene = str(scene)
        self.model, self.layout = load_scene(scene)
        self.data = mujoco.MjData(self.model)
        self._substeps = max(1, round(CONTROL_DT / self.model.opt.timestep))
        self._body_names = tuple(self.model.body(b).name for b in self.layout.moving_bodies)
        self._before_tick = np.zeros(mujoco.mj_stateSize(self.model, STATE))
        self.reset(seed)

    # -- TableWorld ---------------------------------------------------------------------------
    @property
    def objects(self) -> tuple[str, ...]:
        """All object names."""
        return self.layout.objects

    def labels(self) -> frozenset[str]:
        """Objects resting upright in their slot on Table B, judged from the physical state."""
        return frozenset(o for o in self.layout.objects if self.in_slot(o))

    def in_slot(self, obj: str) -> bool:
        """Whether `obj` rests in its slot: centre within tolerance, upright, nearly still, not held."""
        lay, d = self.layout, self.data
        if obj == self._held:
            return False
        b, slot = lay.body[obj], lay.slot[obj]
        pos = d.xpos[b]
        off_slot = np.hypot(*(pos[:2] - slot.pos[:2]))
        height = pos[2] + lay.bottom[obj] - lay.table_top
        upright = d.xmat[b, 8] > 0.9
        speed = np.linalg.norm(d.qvel[lay.dof_adr[obj] : lay.dof_adr[obj] + 3])
        return bool(off_slot <= SLOT_TOLERANCE and -0.01 <= height <= STACK_HEIGHT and upright and speed < REST_SPEED)

    def place(self, obj: str, *, drop: bool = False) -> frozenset[str]:
        """Pick `obj` from Table A and set it in its slot (or let go over the floor if `drop`)."""
        for _ in self.place_frames(obj, drop=drop):
            pass
        return self._trace[-1]

    def place_frames(self, obj: str, *, drop: bool = False) -> Iterator[tuple[float, np.ndarray]]:
        """Like place(), but simulate lazily, yielding (time, body poses) for each recorded frame.

        The request is checked at once; the action ends (and the trace grows) when the iterator is
        exhausted, so consume it fully before the next action.
        """
        self._start_move(obj)
        return self._simulate(obj, drop)

    def _simulate(self, obj: str, drop: bool) -> Iterator[tuple[float, np.ndarray]]:
        yield from self._run(self._plan(obj, drop), obj)
        self._trace.append(self.labels())
        self._done.append((obj, drop))

    # -- clips ----------------------------------------------------------------------------------
    @property
    def history(self) -> tuple[str, int, tuple[tuple[str, bool], ...]] | None:
        """(scene, seed, (object, dropped) per finished action): what fixes the state, physics being
        deterministic; None while an action is under way."""
        if len(self._done) != len(self._moved):
            return None
        return self.scene, self.seed, tuple(self._done)

    def place_clip(self, obj: str) -> Clip:
        """Place `obj` (as place()) and return the placement as a clip that replay() can apply to another world."""
        start = len(self._times)
        self.place(obj)
        return Clip(obj, np.array(self._times[start:]), np.array(self._poses[start:]).reshape(-1, len(self.bodies), 7),
                    self._trace[-1], self._before_tick.copy(), self.model.eq_data.copy(), self._next_frame)

    def replay(self, clip: Clip) -> frozenset[str]:
        """Apply a clip placed on a world with this history: the same frames, labels and state, without simulating
        the placement (one control tick is stepped again); the labels after it."""
        m, d = self.model, self.data
        self._start_move(clip.obj)
        mujoco.mj_setState(m, d, clip.before_last_tick, STATE)
        m.eq_data[:] = clip.eq_data
        mujoco.mj_step(m, d, self._substeps)
        self._before_tick[:] = clip.before_last_tick
        self._times.extend(clip.times.tolist())
        self._poses.extend(clip.poses)
        self._next_frame = clip.next_frame
        self._held = None  # a placement ends with its object let go
        self._trace.append(clip.labels)
        self._done.append((clip.obj, False))
        return clip.labels

    def reset(self, seed: int = 0) -> None:
        """Objects back on Table A with seeded jitter, arm at home, weld off, trace restarted."""
        m, d, lay = self.model, self.data, self.layout
        mujoco.mj_resetData(m, d)
        self.seed = seed
        rng = np.random.default_rng(seed)
        for o in lay.objects:
            adr = lay.qpos_adr[o]
            d.qpos[adr : adr + 2] += rng.uniform(-JITTER_XY, JITTER_XY, size=2)
            base_quat = m.qpos0[adr + 3 : adr + 7].copy()
            mujoco.mju_mulQuat(d.qpos[adr + 3 : adr + 7], _yaw_quat(rng.uniform(-JITTER_YAW, JITTER_YAW)), base_quat)
        d.qpos[lay.arm_qpos] = arm.HOME
        d.ctrl[lay.arm_ctrl] = arm.HOME
        d.ctrl[lay.finger_ctrl] = FINGER_OPEN
        mujoco.mj_forward(m, d)
        self._held = None
        self._moved: list[str] = []
        self._done: list[tuple[str, bool]] = []  # finished actions: (object, dropped)
        self._times: list[float] = []
        self._poses: list[np.ndarray] = []
        self._record()
        self._trace = [self.labels()]

    def close(self) -> None:
        """Free the recorded frames (model and data are freed with the world)."""
        self._times, self._poses = [], []

    # -- recording ----------------------------------------------------------------------------
    @property
    def bodies(self) -> tuple[str, ...]:
        """Names of the bodies that can move (arm links and objects), in pose-array order."""
        return self._body_names

    @property
    def recording(self) -> Recording:
        """Poses of the moving bodies at ~30 frames per simulated second since the last reset."""
        poses = np.array(self._poses).reshape(-1, len(self._body_names), 7)
        return Recording(self._body_names, np.array(self._times), poses)

    def body_poses(self) -> np.ndarray:
        """Current (B, 7) poses of the moving bodies, in `bodies` order."""
        ids = list(self.layout.moving_bodies)
        return np.concatenate([self.data.xpos[ids], self.data.xquat[ids]], axis=1)

    def _record(self) -> None:
        self._times.append(float(self.data.time))
        self._poses.append(self.body_poses())
        self._next_frame = (np.floor(self.data.time / FRAME_DT + 1e-6) + 1) * FRAME_DT

    # -- motion ---------------------------------------------------------------------------------
    def _grip_target(self, pos: np.ndarray, yaw: float, obj: str) -> tuple[np.ndarray, float]:
        grasp = self.layout.grasp[obj]
        return pos + _rot_z(yaw, grasp.pos), yaw + grasp.yaw

    def _stack_top(self, obj: str) -> float:
        """Height of whatever already rests in `obj`'s slot, or the table top."""
        lay, m, d = self.layout, self.model, self.data
        top = lay.table_top
        slot_xy = lay.slot[obj].pos[:2]
        for other in lay.objects:
            b = lay.body[other]
            if other == obj or other == self._held or np.hypot(*(d.xpos[b, :2] - slot_xy)) > 0.06:
                continue
            for g in np.flatnonzero(m.geom_bodyid == b):
                centre = d.geom_xpos[g] + d.geom_xmat[g].reshape(3, 3) @ m.geom_aabb[g, :3]
                reach = np.abs(d.geom_xmat[g].reshape(3, 3)[2]) @ m.geom_aabb[g, 3:]
                top = max(top, float(centre[2] + reach))
        return top

    def _plan(self, obj: str, drop: bool) -> list[tuple[np.ndarray, np.ndarray, str | None]]:
        """Segments of (arm set-points (n, 5), finger set-points (n,), event after the segment)."""
        lay, d = self.layout, self.data
        b = lay.body[obj]
        obj_yaw = float(np.arctan2(d.xmat[b, 3], d.xmat[b, 0]))
        pick, pick_yaw = self._grip_target(d.xpos[b].copy(), obj_yaw, obj)
        slot = lay.slot[obj]
        goal_pos = np.array([slot.pos[0], slot.pos[1], self._stack_top(obj) - lay.bottom[obj] + CLEARANCE])
        put, put_yaw = self._grip_target(goal_pos, slot.yaw, obj)
        hover_z = max(pick[2], put[2]) + HOVER
        above_pick = np.array([pick[0], pick[1], hover_z])
        above_put = np.array([put[0], put[1], hover_z])
        closed = lay.grasp[obj].half_width
        q_now = d.qpos[lay.arm_qpos].copy()
        q_above_pick = arm.solve_ik(lay.arm, above_pick, pick_yaw)
        q_above_put = arm.solve_ik(lay.arm, above_put, put_yaw)
        # Keep the roll continuous so the held object turns the short way.
        q_above_put[4] = q_above_pick[4] + (q_above_put[4] - q_above_pick[4] + np.pi) % (2 * np.pi) - np.pi

        def steps(seconds: float) -> int:
            return max(1, round(seconds / CONTROL_DT))

        def joint(q0: np.ndarray, q1: np.ndarray, seconds: float) -> np.ndarray:
            return q0 + _min_jerk(steps(seconds))[:, None] * (q1 - q0)

        def line(p0: np.ndarray, p1: np.ndarray, yaw: float, roll: float, seconds: float) -> np.ndarray:
            path = arm.solve_ik(lay.arm, p0 + _min_jerk(steps(seconds))[:, None] * (p1 - p0), yaw)
            path[:, 4] = roll  # same roll as the neighbouring joint-space move
            return path

        def hold(q: np.ndarray, seconds: float) -> np.ndarray:
            return np.repeat(q[None], steps(seconds), axis=0)

        def fingers(n: int, start: float, end: float) -> np.ndarray:
            return start + (end - start) * np.linspace(0.0, 1.0, n + 1)[1:]

        pick_roll, put_roll = q_above_pick[4], q_above_put[4]
        descend = line(above_pick, pick, pick_yaw, pick_roll, 0.6)
        lift = line(pick, above_pick, pick_yaw, pick_roll, 0.5)
        segments: list[tuple[np.ndarray, np.ndarray, str | None]] = [
            (joint(q_now, q_above_pick, 1.0), np.full(steps(1.0), FINGER_OPEN), None),
            (descend, np.full(len(descend), FINGER_OPEN), None),
            (hold(descend[-1], 0.25), fingers(steps(0.25), FINGER_OPEN, closed), "grasp"),
            (lift, np.full(len(lift), closed), None),
        ]
        if drop:
            q_drop = arm.solve_ik(lay.arm, np.array([*DROP_XY, hover_z]), pick_yaw)
            segments += [
                (joint(q_above_pick, q_drop, 1.2), np.full(steps(1.2), closed), "release"),
                (hold(q_drop, 0.2), fingers(steps(0.2), closed, FINGER_OPEN), None),
                (joint(q_drop, arm.HOME, 0.8), np.full(steps(0.8), FINGER_OPEN), None),
            ]
            return segments
        transport = joint(q_above_pick, q_above_put, 1.2)
        lower = line(above_put, put, put_yaw, put_roll, 0.6)
        retreat = line(put, above_put, put_yaw, put_roll, 0.4)
        segments += [
            (transport, np.full(len(transport), closed), None),
            (lower, np.full(len(lower), closed), "release"),
            (hold(lower[-1], 0.2), fingers(steps(0.2), closed, FINGER_OPEN), None),
            (retreat, np.full(len(retreat), FINGER_OPEN), None),
            (joint(q_above_put, arm.HOME, 0.8), np.full(steps(0.8), FINGER_OPEN), None),
        ]
        return segments

    def _run(
        self, segments: list[tuple[np.ndarray, np.ndarray, str | None]], obj: str
    ) -> Iterator[tuple[float, np.ndarray]]:
        """Track the set-points, fire grasp/release events, let the objects settle; yield frames."""
        lay, d = self.layout, self.data
        for arm_q, finger_q, event in segments:
            for q, f in zip(arm_q, finger_q, strict=True):
                d.ctrl[lay.arm_ctrl] = q
                d.ctrl[lay.finger_ctrl] = f
                if self._step():
                    yield self._times[-1], self._poses[-1]
            if event == "grasp":
                self._attach(obj)
            elif event == "release":
                d.eq_active[lay.weld[obj]] = 0
                self._held = None
        for _ in range(round(1.0 / CONTROL_DT)):
            if all(np.linalg.norm(d.qvel[lay.dof_adr[o] : lay.dof_adr[o] + 6]) < 0.01 for o in lay.objects):
                break
            if self._step():
                yield self._times[-1], self._poses[-1]

    def _step(self) -> bool:
        """One control tick; True if it recorded a frame."""
        mujoco.mj_getState(self.model, self.data, self._before_tick, STATE)  # for a clip ending with this tick
        mujoco.mj_step(self.model, self.data, self._substeps)
        # Frames follow a fixed 1/30 s schedule, each taken at the first control tick after its time.
        if self.data.time >= self._next_frame - 1e-6:
            self._record()
            return True
        return False

    def _attach(self, obj: str) -> None:
        """Weld `obj` to the hand at their current relative pose (written into this world's model)."""
        lay, m, d = self.layout, self.model, self.data
        hand, b = m.body("hand").id, lay.body[obj]
        rel_pos, rel_quat, hand_inv = np.zeros(3), np.zeros(4), np.zeros(4)
        mujoco.mju_negQuat(hand_inv, d.xquat[hand])
        mujoco.mju_rotVecQuat(rel_pos, d.xpos[b] - d.xpos[hand], hand_inv)
        mujoco.mju_mulQuat(rel_quat, hand_inv, d.xquat[b])
        weld = lay.weld[obj]
        m.eq_data[weld, 0:3] = 0.0
        m.eq_data[weld, 3:6] = rel_pos
        m.eq_data[weld, 6:10] = rel_quat
        d.eq_active[weld] = 1
        self._held = obj
