"""The geometry of a scene with its own objects: the two tables (as in sim_assets/dinner_table/scene.xml), each
shape's dimensions at a size, where each object goes on Table B and where it starts on Table A.

World frame as in the MuJoCo scene: the robot's base at the origin, Table A at +y, Table B at -y, the participant's
camera at +x looking back at the robot. Object frames have their origin at the bottom centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .spec import ObjectSpec

TABLE_A = (0.45, 0.33)  # centre of the top (x, y), metres
TABLE_B = (0.45, -0.33)
TABLE_HALF = (0.22, 0.24)  # half extents of both tops
TABLE_TOP = 0.40  # height of both tops
EDGE_MARGIN = 0.01  # an object keeps this far inside a table's edge
START_GAP = 0.03  # between objects on Table A (their start poses are jittered by up to 8 mm)
SLOT_GAP = 0.01  # between objects' footprints on Table B
MIN_SLOT_DISTANCE = 0.07  # metres between slot centres: the robot sets an object on anything within 6 cm of its slot


@dataclass(frozen=True)
class Dimensions:
    """An object's size and where the gripper holds it, in the object's frame (metres)."""

    half_x: float  # footprint half extents
    half_y: float
    height: float
    grasp: tuple[float, float, float]  # the point between the fingertips
    grasp_half_width: float  # half the thickness the fingers close on
    round: bool  # a disc from above (else a rectangle)


def dimensions(o: ObjectSpec) -> Dimensions:
    """The shape's dimensions at the object's size (cm across: diameter, length or side)."""
    s = o.size / 100.0
    r = s / 2
    if o.shape == "plate":
        return Dimensions(r, r, 0.012, (-(r - 0.012), 0.0, 0.011), 0.006, True)
    if o.shape == "bowl":
        k = s / 0.135  # the dinner bowl is 13.5 cm across
        return Dimensions(r, r, 0.057 * k, (-0.0625 * k, 0.0, 0.05 * k), 0.004, True)
    if o.shape == "cup":
        h = min(0.9 * s, 0.09)
        return Dimensions(r + 0.015, r, h, (-(r - 0.004), 0.0, h - 0.012), 0.004, True)  # the handle at +x
    if o.shape == "glass":
        h = min(1.5 * s, 0.11)
        return Dimensions(r, r, h, (-(r - 0.003), 0.0, h - 0.015), 0.003, True)
    if o.shape == "utensil":  # along x, tip at -x, handle at +x (as the dinner knife)
        return Dimensions(r, 0.009, 0.012, (0.27 * s, 0.0, 0.01), 0.008, False)
    if o.shape == "box":
        h = max(0.5 * s, 0.04)
        return Dimensions(r, r, h, (-(r - 0.008), 0.0, h - 0.008), 0.008, False)
    raise ValueError(f"unknown shape {o.shape!r}")


def slot_pose(o: ObjectSpec) -> tuple[float, float, float]:
    """World (x, y, yaw) of an object in its slot: the slot's picture coordinates turned into the world frame."""
    return TABLE_B[0] - o.slot.y / 100.0, TABLE_B[1] + o.slot.x / 100.0, 0.0


def start_yaw(o: ObjectSpec) -> float:
    """An object's yaw on Table A: utensils lie across the table, as the dinner cutlery does."""
    return math.pi / 2 if o.shape == "utensil" else 0.0


def footprint(o: ObjectSpec, x: float, y: float, yaw: float) -> tuple[float, float, float, float]:
    """The world-axis rectangle (x0, x1, y0, y1) an object covers at this pose (yaw 0 or a quarter turn)."""
    d = dimensions(o)
    hx, hy = (d.half_y, d.half_x) if abs(math.sin(yaw)) > 0.5 else (d.half_x, d.half_y)
    return x - hx, x + hx, y - hy, y + hy


def gap_between(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """The clearance between two rectangles (negative when they overlap)."""
    dx = max(a[0], b[0]) - min(a[1], b[1])
    dy = max(a[2], b[2]) - min(a[3], b[3])
    return max(dx, dy)


def on_table(rect: tuple[float, float, float, float], table: tuple[float, float]) -> bool:
    """Whether a rectangle lies on a table's top, EDGE_MARGIN inside its edge."""
    return (rect[0] >= table[0] - TABLE_HALF[0] + EDGE_MARGIN and rect[1] <= table[0] + TABLE_HALF[0] - EDGE_MARGIN
            and rect[2] >= table[1] - TABLE_HALF[1] + EDGE_MARGIN and rect[3] <= table[1] + TABLE_HALF[1] - EDGE_MARGIN)


def grip_point(o: ObjectSpec, x: float, y: float, yaw: float, lift: float = 0.0) -> tuple[float, float, float]:
    """Where the fingertips close on an object resting on a table top at (x, y, yaw), raised by `lift`."""
    g = dimensions(o).grasp
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * g[0] - s * g[1], y + s * g[0] + c * g[1], TABLE_TOP + g[2] + lift
