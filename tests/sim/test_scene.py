"""The dinner-table asset: names, robot, slots and provenance the rest of the code relies on."""

import re
from pathlib import Path

import mujoco
import numpy as np

from tableteach.sim import OBJECTS
from tableteach.sim.scene import SCENE_XML, load_scene

ASSETS = SCENE_XML.parent


def test_scene_has_objects_robot_camera_and_lights():
    model, layout = load_scene()
    assert layout.objects == OBJECTS
    hinges = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    assert len(hinges) >= 5
    assert model.nu >= 7  # five arm joints and two fingers
    assert "overview" in [model.camera(i).name for i in range(model.ncam)]
    assert model.nlight >= 1
    assert all(model.eq_active0[layout.weld[o]] == 0 for o in OBJECTS)


def test_slots_form_a_place_setting_on_table_b():
    model, layout = load_scene()
    table_b = model.body("table_b").id
    for obj in OBJECTS:
        assert model.site_bodyid[model.site(f"slot_{obj}").id] == table_b
    centre = layout.slot["dinner_plate"].pos
    for stacked in ("small_plate", "bowl"):
        np.testing.assert_allclose(layout.slot[stacked].pos[:2], centre[:2])
    # The diner sits at +x facing the robot, so their left is -y.
    assert layout.slot["fork"].pos[1] < centre[1] < layout.slot["knife"].pos[1]


def test_objects_start_on_table_a():
    model, layout = load_scene()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    top = model.geom("table_a_top")
    for obj in OBJECTS:
        pos = data.xpos[layout.body[obj]]
        offset = np.abs(pos[:2] - (model.body("table_a").pos[:2] + top.pos[:2]))
        assert np.all(offset < top.size[:2]), obj


def test_each_world_gets_its_own_model():
    first, _ = load_scene()
    second, _ = load_scene()
    first.eq_data[0, 3] = 123.0
    assert second.eq_data[0, 3] != 123.0


def test_every_asset_file_has_provenance():
    readme = (ASSETS.parents[0] / "README.md").read_text()
    for path in ASSETS.rglob("*"):
        if path.is_file() and path.suffix in {".xml", ".obj", ".py"}:
            assert path.name in readme, f"{path.name} missing from sim_assets/README.md"
    assert re.search(r"hand-written", readme)
    meshes = [p.name for p in Path(ASSETS, "meshes").glob("*")]
    assert meshes == ["bowl.obj"]
