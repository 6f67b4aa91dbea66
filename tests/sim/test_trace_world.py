"""The trace-only world: same interface and refusals as physics, no mujoco anywhere."""

import subprocess
import sys

import pytest

from tableteach.sim import OBJECTS, PlacementError, TableWorld, TraceWorld


def test_package_and_trace_world_import_without_mujoco_or_viser():
    code = (
        "import sys, tableteach.sim, tableteach.sim.trace_world, tableteach.sim.world; "
        "print(sorted(m for m in ('mujoco', 'viser') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_trace_world_satisfies_the_protocol():
    assert isinstance(TraceWorld(), TableWorld)


def test_placing_records_labels_after_every_action():
    world = TraceWorld()
    assert world.trace == [frozenset()]
    assert world.place("bowl") == {"bowl"}
    world.place("knife")
    assert world.placed == ("bowl", "knife")
    assert world.trace == [frozenset(), frozenset({"bowl"}), frozenset({"bowl", "knife"})]


def test_dropped_object_stays_false_but_counts_as_moved():
    world = TraceWorld()
    assert world.place("fork", drop=True) == frozenset()
    assert world.placed == ("fork",)
    with pytest.raises(PlacementError, match="'fork' was already moved"):
        world.place("fork")


def test_refuses_unknown_and_repeated_objects_with_clear_messages():
    world = TraceWorld()
    world.place("bowl")
    with pytest.raises(ValueError, match=r"unknown object 'spoon': expected one of .*dinner_plate"):
        world.place("spoon")
    with pytest.raises(PlacementError, match=r"'bowl' was already moved .* expected one of .*knife"):
        world.place("bowl")
    assert world.trace == [frozenset(), frozenset({"bowl"})]


def test_reset_restarts_the_trace():
    world = TraceWorld()
    for obj in OBJECTS:
        world.place(obj)
    assert world.labels() == frozenset(OBJECTS)
    world.reset(7)
    assert world.trace == [frozenset()] and world.placed == ()


def test_the_trace_robot_refuses_an_execution_it_cannot_carry_out_as_the_mujoco_robot_does():
    from tableteach.robot import TraceRobot

    robot = TraceRobot()
    with pytest.raises(ValueError, match="'fork' is already placed"):
        robot.plan_execution("t", ["fork", "bowl", "fork"], "participant-x/task-0/query-0")
    with pytest.raises(ValueError, match="unknown action 'spoon'"):
        robot.plan_execution("t", ["spoon"], "participant-x/task-0/query-0")
    plan = robot.plan_execution("t", ["fork", "bowl"], "participant-x/task-0/query-0")
    assert plan.events == ("fork", "bowl")
    assert plan.trace == (frozenset(), frozenset({"fork"}), frozenset({"fork", "bowl"}))
