"""Whether the scene's arm can pick an object up or set it down at a pose, from the arm's kinematics.

The numbers are the arm of sim_assets/dinner_table/scene.xml (every generated scene has the same arm), read the
way tableteach.sim.scene reads them; tests/sim/test_scene_mjcf.py checks them against the model. The robot holds
its hand straight down: base yaw fixes the arm's plane, shoulder and elbow put the wrist over the grip point, the
wrist pitch points the hand down (tableteach.sim.arm). Every grip point the robot's motion passes through (on
the table and HOVER above it, and the straight descent between) must have a solution within the joints' ranges.
"""

from __future__ import annotations

import math

from .geometry import grip_point
from .spec import ObjectSpec

SHOULDER_Z = 0.50  # the shoulder axis above the floor (pedestal 0.40 + turret 0.10), at the base's centre
UPPER, FORE, HAND = 0.42, 0.38, 0.17  # shoulder -> elbow, elbow -> wrist pitch, wrist pitch -> grip point
# Joint ranges (radians) of shoulder, elbow and wrist pitch, each narrowed by a margin for the servos' tracking.
RANGES = {"shoulder": (-1.2, 2.2), "elbow": (-0.2, 2.8), "wrist_pitch": (-0.5, 3.3)}
MARGIN = 0.05
HOVER = 0.12  # the robot approaches and leaves a grip point from this far above (sim.physics.HOVER)
CLEARANCE = 0.004  # an object is set down this far above the table (sim.physics.CLEARANCE)
DESCENT_SAMPLES = 6


def joint_problem(x: float, y: float, z: float) -> str | None:
    """None if the hand can hold a grip point at (x, y, z) pointing down, else what stops it."""
    u = math.hypot(x, y)
    v = z + HAND - SHOULDER_Z
    cos_elbow = (u * u + v * v - UPPER * UPPER - FORE * FORE) / (2 * UPPER * FORE)
    if cos_elbow < -1.0:
        return "too close to the robot's base"
    if cos_elbow > 1.0:
        return (f"{u * 100:.1f} cm from the robot's base, and the arm reaches at most {reach_radius(z) * 100:.1f} cm "
                "out at the height it carries it")
    elbow = math.acos(cos_elbow)
    shoulder = math.atan2(u, v) - math.atan2(FORE * math.sin(elbow), UPPER + FORE * math.cos(elbow))
    angles = {"shoulder": shoulder, "elbow": elbow, "wrist_pitch": math.pi - shoulder - elbow}
    for joint, angle in angles.items():
        low, high = RANGES[joint]
        if not low + MARGIN <= angle <= high - MARGIN:
            where = "too close to the robot's base" if u < 0.4 else f"{u * 100:.1f} cm from the robot's base, too far"
            return f"{where} (the {joint.replace('_', ' ')} would have to turn past its limit)"
    return None


def reach_radius(z: float) -> float:
    """How far from the base's axis the arm holds a grip point at height z (the elbow stretched)."""
    v = z + HAND - SHOULDER_Z
    return math.sqrt(max((UPPER + FORE) ** 2 - v * v, 0.0))


def reach_problem(o: ObjectSpec, x: float, y: float, yaw: float) -> str | None:
    """None if the arm can set `o` down (or pick it up) at world (x, y, yaw) on a table top, else why not."""
    for i in range(DESCENT_SAMPLES + 1):
        problem = joint_problem(*grip_point(o, x, y, yaw, CLEARANCE + HOVER * i / DESCENT_SAMPLES))
        if problem is not None:
            return problem
    return None
