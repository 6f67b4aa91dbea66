"""The MuJoCo world: every order ends in the place setting, labels come from the physical state."""

import itertools

import mujoco
import numpy as np
import pytest

from tableteach.sim import OBJECTS, PlacementError, TableWorld
from tableteach.sim.physics import SLOT_TOLERANCE, MujocoWorld

STACK = ("dinner_plate", "small_plate", "bowl", "knife")


def _orders() -> list[tuple[str, ...]]:
    """All 24 orders of four objects (every stacking order) with the fork at every position: each
    object lands in each of the five positions. All 120 orders pass too but take about 20 s each core."""
    orders = []
    for i, perm in enumerate(itertools.permutations(STACK)):
        order = list(perm)
        order.insert(i % 5, "fork")
        orders.append(tuple(order))
    return orders


def test_order_sample_covers_every_object_in_every_position():
    positions = {(obj, order.index(obj)) for order in _orders() for obj in order}
    assert positions == {(obj, k) for obj in OBJECTS for k in range(5)}


@pytest.fixture(scope="module")
def world():
    w = MujocoWorld(seed=0)
    yield w
    w.close()


def test_mujoco_world_satisfies_the_protocol(world):
    assert isinstance(world, TableWorld)


@pytest.mark.parametrize("order", _orders(), ids="-".join)
def test_every_order_ends_with_each_object_in_its_slot(world, order):
    world.reset(seed=len(order[0]))
    for obj in order:
        world.place(obj)
    expected = [frozenset(order[:k]) for k in range(len(order) + 1)]
    assert world.trace == expected
    for obj in OBJECTS:
        pos = world.data.xpos[world.layout.body[obj]]
        assert np.hypot(*(pos[:2] - world.layout.slot[obj].pos[:2])) < SLOT_TOLERANCE


def test_forced_drop_leaves_the_proposition_false(world):
    world.reset(1)
    world.place("bowl")
    assert world.place("dinner_plate", drop=True) == {"bowl"}
    plate = world.data.xpos[world.layout.body["dinner_plate"]]
    assert plate[2] < 0.1  # on the floor, not on a table
    assert world.place("knife") == {"bowl", "knife"}
    assert world.placed == ("bowl", "dinner_plate", "knife")
    with pytest.raises(PlacementError, match="'dinner_plate' was already moved"):
        world.place("dinner_plate")


def test_refuses_unknown_and_repeated_objects(world):
    world.reset(2)
    world.place("fork")
    before = world.data.qpos.copy()
    with pytest.raises(ValueError, match=r"unknown object 'teapot': expected one of the objects on Table A"):
        world.place("teapot")
    with pytest.raises(PlacementError, match=r"'fork' .* cannot be picked up again: expected one of .*bowl"):
        world.place("fork")
    np.testing.assert_array_equal(world.data.qpos, before)
    assert world.trace == [frozenset(), frozenset({"fork"})]


def test_labels_read_the_physical_state_not_the_commands(world):
    world.reset(3)
    world.place("knife")
    assert world.labels() == {"knife"}
    lay, data = world.layout, world.data
    # Knock the knife out of its slot by hand: the proposition follows the state.
    data.qpos[lay.qpos_adr["knife"]] += 0.1
    mujoco.mj_forward(world.model, data)
    assert world.labels() == frozenset()
    # Set the fork (never commanded) into its slot: it counts as placed.
    adr = lay.qpos_adr["fork"]
    data.qpos[adr : adr + 3] = lay.slot["fork"].pos
    data.qpos[adr + 3 : adr + 7] = [1, 0, 0, 0]
    mujoco.mj_forward(world.model, data)
    assert world.labels() == {"fork"}
    # A moving object is not at rest, so not placed.
    data.qvel[lay.dof_adr["fork"]] = 0.5
    assert world.labels() == frozenset()


def test_same_seed_same_motion_other_seed_other_start():
    first, second, other = MujocoWorld(seed=5), MujocoWorld(seed=5), MujocoWorld(seed=6)
    for w in (first, second):
        w.place("small_plate")
        w.place("fork")
    np.testing.assert_array_equal(first.data.qpos, second.data.qpos)
    np.testing.assert_array_equal(first.recording.poses, second.recording.poses)
    assert first.trace == second.trace
    assert not np.allclose(first.recording.poses[0], other.recording.poses[0])
    first.reset(6)
    np.testing.assert_array_equal(first.recording.poses[0], other.recording.poses[0])


def test_two_sessions_never_disturb_each_other():
    a, b = MujocoWorld(seed=0), MujocoWorld(seed=0)
    solo_a, solo_b = MujocoWorld(seed=0), MujocoWorld(seed=0)
    for obj_a, obj_b in [("dinner_plate", "bowl"), ("small_plate", "knife"), ("bowl", "dinner_plate")]:
        a.place(obj_a)
        b.place(obj_b)
    for obj in ("dinner_plate", "small_plate", "bowl"):
        solo_a.place(obj)
    for obj in ("bowl", "knife", "dinner_plate"):
        solo_b.place(obj)
    # Interleaving with another world changes nothing, bit for bit, for either of them.
    np.testing.assert_array_equal(a.data.qpos, solo_a.data.qpos)
    np.testing.assert_array_equal(b.data.qpos, solo_b.data.qpos)


def test_a_grasp_in_one_world_does_not_move_objects_in_the_other():
    a, b = MujocoWorld(seed=0), MujocoWorld(seed=0)
    reference = b.model.eq_data.copy()
    bowl = a.layout.body["bowl"]
    a._attach("bowl")  # writes the grasp pose into a's model and activates a's weld
    a.data.ctrl[a.layout.arm_ctrl[0]] += 0.5  # swing a's base: its bowl follows the hand
    start_a, start_b = a.data.xpos[bowl].copy(), b.data.xpos[bowl].copy()
    for _ in range(200):
        mujoco.mj_step(a.model, a.data)
        mujoco.mj_step(b.model, b.data)
    assert np.linalg.norm(a.data.xpos[bowl] - start_a) > 0.05
    np.testing.assert_allclose(b.data.xpos[bowl], start_b, atol=1e-4)
    np.testing.assert_array_equal(b.model.eq_data, reference)
    assert b.data.eq_active.sum() == 0


def test_recording_has_about_thirty_frames_per_simulated_second(world):
    world.reset(4)
    world.place("bowl")
    rec = world.recording
    assert set(OBJECTS) <= set(rec.bodies) and "hand" in rec.bodies
    assert 28 <= len(rec) / rec.duration <= 32
    bowl = rec.bodies.index("bowl")
    np.testing.assert_allclose(rec.poses[-1, bowl, :3], world.data.xpos[world.layout.body["bowl"]])


def test_place_frames_simulates_lazily_and_matches_place(world):
    world.reset(4)
    with pytest.raises(PlacementError):
        world.place_frames("spoon")  # refused at the call, not at the first frame
    frames = world.place_frames("knife")
    first = next(frames)
    assert world.trace == [frozenset()]  # the action is not over yet
    rest = list(frames)
    assert world.trace == [frozenset(), frozenset({"knife"})]
    rec = world.recording
    np.testing.assert_array_equal(rec.poses[1:], np.array([first[1]] + [p for _, p in rest]))
    eager = MujocoWorld(seed=4)
    eager.place("knife")
    np.testing.assert_array_equal(eager.data.qpos, world.data.qpos)
