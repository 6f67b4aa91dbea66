"""Scenes generated from a study's own objects: MuJoCo loads them, the arm sets every object in its slot (MuJoCo's
state says so), the text is deterministic and content-addressed, and the pure reach check agrees with the arm."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tableteach.scenes import reach
from tableteach.scenes.geometry import TABLE_A, TABLE_B, TABLE_HALF, TABLE_TOP
from tableteach.scenes.layout import scene_problems, start_poses
from tableteach.scenes.spec import SIZE_RANGES, ObjectSpec, SceneSpec, Slot
from tableteach.sim import arm
from tableteach.sim.physics import MujocoWorld
from tableteach.sim.scene import SCENE_XML, load_scene, scene_objects
from tableteach.sim.scene_mjcf import scene_path, scene_xml

from tests.study_objects import EIGHT_OBJECTS, LUNCH_OBJECTS, TEN_OBJECTS

EIGHT = SceneSpec.from_json(EIGHT_OBJECTS)
TEN = SceneSpec.from_json(TEN_OBJECTS)


@pytest.mark.parametrize("spec", [EIGHT, TEN], ids=["eight", "ten"])
def test_eight_or_ten_objects_of_every_shape_are_each_set_in_their_slot_by_the_arm(tmp_path: Path,
                                                                                   spec: SceneSpec) -> None:
    assert list(scene_problems(spec)) == []
    world = MujocoWorld(seed=7, scene=scene_path(spec, tmp_path))
    assert world.objects == spec.names
    assert world.labels() == frozenset()
    for i, obj in enumerate(spec.names):
        labels = world.place(obj)
        assert labels == frozenset(spec.names[: i + 1]), (obj, sorted(labels))
    # MuJoCo's state: each object rests upright, still and centred in its slot, on the table top.
    for obj in spec.names:
        body = world.layout.body[obj]
        slot = world.layout.slot[obj].pos
        assert math.hypot(*(world.data.xpos[body][:2] - slot[:2])) < 0.02, obj
        assert world.data.xmat[body, 8] > 0.95, obj
        assert abs(world.data.xpos[body][2] + world.layout.bottom[obj] - TABLE_TOP) < 0.01, obj
        assert world.in_slot(obj)
    assert world.trace[-1] == frozenset(spec.names)


@pytest.mark.parametrize("shape", sorted(SIZE_RANGES))
def test_every_shape_at_its_smallest_and_largest_size_is_carried_to_its_slot(tmp_path: Path, shape: str) -> None:
    low, high = SIZE_RANGES[shape]
    spec = SceneSpec((ObjectSpec("small", shape, "#aa3322", low, Slot(-17, 13)),
                      ObjectSpec("large", shape, "#22aa33", high, Slot(5, -3))))
    assert list(scene_problems(spec)) == []
    world = MujocoWorld(seed=3, scene=scene_path(spec, tmp_path))
    world.place("large")
    assert world.place("small") == frozenset({"small", "large"})


def test_the_scene_text_is_a_function_of_the_specification_and_its_file_is_named_by_its_digest(tmp_path: Path) -> None:
    again = SceneSpec.from_json([dict(o) for o in EIGHT_OBJECTS])
    assert scene_xml(again) == scene_xml(EIGHT)
    first, second = scene_path(EIGHT, tmp_path / "a"), scene_path(again, tmp_path / "b")
    assert first.name == second.name and first.read_bytes() == second.read_bytes()
    other = SceneSpec.from_json([{**EIGHT_OBJECTS[0], "colour": "#000000"}, *EIGHT_OBJECTS[1:]])
    assert scene_path(other, tmp_path / "a").name != first.name
    model, layout = load_scene(first)
    assert scene_objects(model) == EIGHT.names and layout.objects == EIGHT.names
    # The dinner scene is untouched: its objects are read as before.
    dinner, dinner_layout = load_scene(SCENE_XML)
    assert dinner_layout.objects == ("dinner_plate", "small_plate", "bowl", "knife", "fork")


def test_generated_scenes_keep_the_dinner_scenes_tables_and_arm(tmp_path: Path) -> None:
    dinner_model, dinner = load_scene(SCENE_XML)
    model, own = load_scene(scene_path(SceneSpec.from_json(LUNCH_OBJECTS), tmp_path))
    assert own.arm == dinner.arm
    for table in ("table_a_top", "table_b_top"):
        assert np.allclose(model.geom(table).size, dinner_model.geom(table).size)
    assert np.allclose(model.body("table_a").pos[:2], TABLE_A) and np.allclose(model.body("table_b").pos[:2], TABLE_B)
    assert np.allclose(dinner_model.geom("table_a_top").size[:2], TABLE_HALF)


def test_the_pure_reach_check_uses_the_arm_of_the_scene_and_agrees_with_its_inverse_kinematics() -> None:
    model, layout = load_scene(SCENE_XML)
    geometry = layout.arm
    assert (geometry.shoulder_z, geometry.upper, geometry.fore) == pytest.approx(
        (reach.SHOULDER_Z, reach.UPPER, reach.FORE))
    assert geometry.hand == pytest.approx(reach.HAND) and geometry.base_xy == (0.0, 0.0)
    for joint, (low, high) in reach.RANGES.items():
        assert tuple(model.joint(joint).range) == pytest.approx((low, high))
    rng = np.random.default_rng(0)
    agreed = 0
    for x, y, z in rng.uniform((-0.1, -0.9, 0.38), (0.95, 0.9, 0.6), size=(400, 3)):
        problem = reach.joint_problem(x, y, z)
        try:
            q = arm.solve_ik(geometry, np.array([x, y, z]), 0.0)
        except arm.UnreachableError:
            assert problem is not None
            continue
        within = all(low + reach.MARGIN <= q[i] <= high - reach.MARGIN
                     for i, (low, high) in zip((1, 2, 3), reach.RANGES.values(), strict=True))
        assert (problem is None) == within
        agreed += problem is None
    assert agreed > 50


def test_the_objects_start_on_table_a_apart_and_within_reach() -> None:
    start = start_poses(EIGHT)
    assert not isinstance(start, str)
    assert set(start) == set(EIGHT.names)
    for o in EIGHT.objects:
        x, y, yaw = start[o.name]
        assert abs(x - TABLE_A[0]) < TABLE_HALF[0] and abs(y - TABLE_A[1]) < TABLE_HALF[1]
        assert reach.reach_problem(o, x, y, yaw) is None
    too_many = SceneSpec(tuple(ObjectSpec(f"plate_{i}", "plate", "#ffffff", 28, Slot(0, 0)) for i in range(4)))
    message = start_poses(too_many)
    assert isinstance(message, str) and "do not all fit on Table A" in message and "plate" in message
