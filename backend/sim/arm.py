"""Closed-form inverse kinematics for the scene's 5-joint arm holding its gripper straight down.

Joints: base_yaw (about z), shoulder, elbow and wrist_pitch (parallel axes, links point up at zero),
wrist_roll (about the hand axis). With the hand vertical, base yaw fixes the arm's plane, shoulder and
elbow solve a planar two-link problem for the wrist, wrist_pitch makes the three pitches sum to pi,
and wrist_roll sets the direction the fingers close in. All functions accept batches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Joint angles of the resting pose: upper arm leaning back, hand down, above the gap between tables.
HOME = np.array([0.0, -0.15, 2.0, np.pi - 1.85, np.pi / 2])


class UnreachableError(ValueError):
    """A gripper target outside the arm's workspace."""


@dataclass(frozen=True)
class ArmGeometry:
    """Link lengths (metres) read from the model; see tableteach.sim.scene."""

    base_xy: tuple[float, float]
    shoulder_z: float
    upper: float  # shoulder axis -> elbow axis
    fore: float  # elbow axis -> wrist-pitch axis
    hand: float  # wrist-pitch axis -> grip point between the fingertips


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def solve_ik(arm: ArmGeometry, grip: np.ndarray, finger_yaw: np.ndarray | float) -> np.ndarray:
    """Joint angles (..., 5) putting the grip point at `grip` (..., 3), hand down, fingers closing
    along world angle `finger_yaw`; raises UnreachableError outside the workspace."""
    grip = np.asarray(grip, dtype=float)
    dx = grip[..., 0] - arm.base_xy[0]
    dy = grip[..., 1] - arm.base_xy[1]
    yaw = np.arctan2(dy, dx)
    u = np.hypot(dx, dy)
    v = grip[..., 2] + arm.hand - arm.shoulder_z
    cos_elbow = (u**2 + v**2 - arm.upper**2 - arm.fore**2) / (2 * arm.upper * arm.fore)
    if np.any(np.abs(cos_elbow) > 1.0):
        bad = np.asarray(grip).reshape(-1, 3)[np.abs(np.ravel(cos_elbow)) > 1.0][0]
        raise UnreachableError(
            f"grip target {np.round(bad, 3).tolist()} is out of reach: expected its wrist point within "
            f"{arm.upper + arm.fore:.2f} m of the shoulder at z={arm.shoulder_z:.2f}"
        )
    elbow = np.arccos(cos_elbow)  # positive: elbow up
    shoulder = np.arctan2(u, v) - np.arctan2(arm.fore * np.sin(elbow), arm.upper + arm.fore * np.cos(elbow))
    wrist_pitch = np.pi - shoulder - elbow
    # With the hand flipped down, the fingers close along world angle yaw + pi/2 - roll.
    roll = _wrap(yaw + np.pi / 2 - np.asarray(finger_yaw, dtype=float))
    return np.stack(np.broadcast_arrays(yaw, shoulder, elbow, wrist_pitch, roll), axis=-1)


def forward(arm: ArmGeometry, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grip point (..., 3) and finger-closing yaw (...) for joint angles q (..., 5) (yaw: hand down)."""
    q = np.asarray(q, dtype=float)
    yaw, shoulder, elbow, pitch, roll = (q[..., i] for i in range(5))
    a1, a2, a3 = shoulder, shoulder + elbow, shoulder + elbow + pitch
    u = arm.upper * np.sin(a1) + arm.fore * np.sin(a2) + arm.hand * np.sin(a3)
    z = arm.shoulder_z + arm.upper * np.cos(a1) + arm.fore * np.cos(a2) + arm.hand * np.cos(a3)
    pos = np.stack([arm.base_xy[0] + u * np.cos(yaw), arm.base_xy[1] + u * np.sin(yaw), z], axis=-1)
    return pos, _wrap(yaw + np.pi / 2 - roll)
