"""Where a scene's objects start on Table A (laid out automatically) and whether their goal layout on Table B works:
each slot on the table, clear of the others, and within the arm's reach."""

from __future__ import annotations

import math
from collections.abc import Iterator
from functools import lru_cache

from .geometry import (EDGE_MARGIN, MIN_SLOT_DISTANCE, SLOT_GAP, START_GAP, TABLE_A, TABLE_B, TABLE_HALF, dimensions,
                       footprint, gap_between, on_table, slot_pose, start_yaw)
from .reach import reach_problem
from .spec import ObjectSpec, SceneSpec

START_GRID = 0.01  # metres between the candidate start positions tried on Table A
Pose = tuple[float, float, float]
# A table's start poses are jittered by up to 8 mm (sim.physics.JITTER_XY): the arm must reach them all.
JITTER_CORNERS = ((0.0, 0.0), (-0.01, -0.01), (-0.01, 0.01), (0.01, -0.01), (0.01, 0.01))


def _label(o: ObjectSpec) -> str:
    return o.name.replace("_", " ")


def slot_problems(spec: SceneSpec) -> Iterator[tuple[int, str]]:
    """(object index, message) for every slot off Table B, too close to another, or out of the arm's reach."""
    rects: dict[int, tuple[float, float, float, float]] = {}
    for i, o in enumerate(spec.objects):
        x, y, yaw = slot_pose(o)
        rect = footprint(o, x, y, yaw)
        where = f"its place at x {o.slot.x:g}, y {o.slot.y:g} cm"
        if not on_table(rect, TABLE_B):
            d = dimensions(o)
            limit_x = (TABLE_HALF[1] - EDGE_MARGIN - d.half_y) * 100
            limit_y = (TABLE_HALF[0] - EDGE_MARGIN - d.half_x) * 100
            yield i, (f"the {_label(o)} would hang over Table B's edge at {where}: for this {o.shape}, x must lie "
                      f"within ±{limit_x:.0f} cm and y within ±{limit_y:.0f} cm of the table's centre")
            continue
        problem = reach_problem(o, x, y, yaw)
        if problem is not None:
            yield i, f"the arm cannot reach the {_label(o)} at {where}: it is {problem}; move it towards the robot"
            continue
        for j, other in rects.items():
            ox, oy, _ = slot_pose(spec.objects[j])
            apart = math.hypot(x - ox, y - oy)
            if gap_between(rect, other) < SLOT_GAP or apart < MIN_SLOT_DISTANCE:
                yield i, (f"the {_label(o)}'s place overlaps the {_label(spec.objects[j])}'s: their centres are "
                          f"{apart * 100:.0f} cm apart; leave at least {SLOT_GAP * 100:.0f} cm between them and "
                          f"{MIN_SLOT_DISTANCE * 100:.0f} cm between their centres")
                break
        rects[i] = rect


@lru_cache(maxsize=64)
def start_poses(spec: SceneSpec) -> dict[str, Pose] | str:
    """Where each object starts on Table A (world x, y, yaw): the largest first, each at the candidate position
    nearest the robot that leaves room beside the others and that the arm reaches; or a message naming the first
    object that finds no room."""
    order = sorted(range(len(spec.objects)), key=lambda i: (-_area(spec.objects[i]), i))
    candidates = _candidates()
    placed: dict[str, Pose] = {}
    rects: list[tuple[float, float, float, float]] = []
    for i in order:
        o = spec.objects[i]
        yaw = start_yaw(o)
        for x, y in candidates:
            rect = footprint(o, x, y, yaw)
            if not on_table(rect, TABLE_A) or any(gap_between(rect, r) < START_GAP for r in rects):
                continue
            if any(reach_problem(o, x + dx, y + dy, yaw) is not None for dx, dy in JITTER_CORNERS):
                continue
            placed[o.name] = (x, y, yaw)
            rects.append(rect)
            break
        else:
            return (f"the objects do not all fit on Table A where the arm reaches them (no room was left for the "
                    f"{_label(o)}); use fewer or smaller objects")
    return {o.name: placed[o.name] for o in spec.objects}


def _area(o: ObjectSpec) -> float:
    d = dimensions(o)
    return d.half_x * d.half_y


@lru_cache(maxsize=1)
def _candidates() -> tuple[tuple[float, float], ...]:
    """Positions on Table A, 1 cm apart, nearest the robot's base first (ties in a fixed order)."""
    nx = int(round(2 * TABLE_HALF[0] / START_GRID))
    ny = int(round(2 * TABLE_HALF[1] / START_GRID))
    x0, y0 = TABLE_A[0] - TABLE_HALF[0], TABLE_A[1] - TABLE_HALF[1]
    points = [(round(x0 + i * START_GRID, 4), round(y0 + j * START_GRID, 4))
              for i in range(nx + 1) for j in range(ny + 1)]
    return tuple(sorted(points, key=lambda p: (round(math.hypot(*p), 6), p)))


def scene_problems(spec: SceneSpec) -> Iterator[tuple[str, str]]:
    """(field, message) for everything wrong with a scene of distinct, valid objects: slots that do not work,
    objects that do not fit on Table A."""
    bad_slots = list(slot_problems(spec))
    for i, message in bad_slots:
        yield f"objects.{i}.slot", message
    if not bad_slots:
        start = start_poses(spec)
        if isinstance(start, str):
            yield "objects", start


