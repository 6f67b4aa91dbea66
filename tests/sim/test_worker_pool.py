"""Robot worker processes: the same plan and files as working an execution out in the server process."""

from __future__ import annotations

import sys
import uuid

import pytest

from tableteach.sim.motion_file import viser_path
from tableteach.sim.recordings import RecordingId, load_recording
from tableteach.sim.robot import MujocoRobot, table_seed
from tableteach.sim.work_out import StudioSource, work_out_execution
from tableteach.sim.worker_pool import ExecutionWorkers, WorkerFailed

EVENTS = ("dinner_plate", "fork", "bowl")


@pytest.fixture(scope="module")
def workers():
    pool = ExecutionWorkers(1)
    yield pool
    pool.close()


def _rid(kind: str = "query", index: int = 0) -> RecordingId:
    return RecordingId(uuid.uuid4().hex, 0, kind, index)


def test_a_worker_works_out_what_the_server_process_would(workers, tmp_path) -> None:
    here, there = tmp_path / "here", tmp_path / "there"
    studio = StudioSource()
    try:
        rid = _rid()
        local = work_out_execution(studio, here, table_seed("k"), EVENTS, rid, 1.5)
    finally:
        studio.close()
    remote = workers.run(there, table_seed("k"), EVENTS, rid, 1.5)
    assert remote == local
    assert remote.trace[-1] == frozenset(EVENTS) and len(remote.action_ends) == len(EVENTS)
    assert viser_path(there, rid).read_bytes() == viser_path(here, rid).read_bytes()
    assert load_recording(there, rid).trace == load_recording(here, rid).trace


def test_a_sequence_the_robot_refuses_is_a_value_error_naming_it(workers, tmp_path) -> None:
    with pytest.raises(ValueError, match="teapot"):
        workers.run(tmp_path, 1, ("teapot",), _rid(), 1.0)
    with pytest.raises(ValueError, match="fork"):
        workers.run(tmp_path, 1, ("fork", "fork"), _rid(), 1.0)
    assert not any(tmp_path.rglob("*.viser"))


def test_a_killed_worker_is_started_again_and_the_execution_still_completes(workers, tmp_path) -> None:
    workers.run(tmp_path, 2, ("bowl",), _rid(), 1.0)
    (worker,) = workers._all
    old = worker.proc
    assert old is not None
    old.kill()
    old.wait()
    plan = workers.run(tmp_path, 2, ("knife",), _rid("test"), 1.0)
    assert plan.trace[-1] == frozenset({"knife"})
    assert worker.proc is not None and worker.proc.pid != old.pid


def test_the_robot_hands_executions_to_its_workers_and_stops_them_at_shutdown(tmp_path) -> None:
    robot = MujocoRobot(data_dir=tmp_path, workers=2)
    try:
        rid = _rid()
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(2) as pool:  # as two runtime job threads would
            futures = [pool.submit(robot.plan_execution, "k", EVENTS, rid.name),
                       pool.submit(robot.plan_execution, "j", ("bowl",), _rid("test").name)]
            plans = [f.result(timeout=120) for f in futures]
        assert plans[0].trace[-1] == frozenset(EVENTS) and plans[1].trace[-1] == frozenset({"bowl"})
        assert robot.plan_execution("k", EVENTS, rid.name) == plans[0]  # remembered, not worked out again
        procs = [w.proc for w in robot._workers._all if w.proc is not None]
        assert procs
    finally:
        robot.shutdown()
    assert all(p.poll() is not None for p in procs)


def test_workers_that_cannot_run_leave_the_execution_to_the_server_process(tmp_path) -> None:
    broken = ExecutionWorkers(1, command=(sys.executable, "-c", "import sys; sys.exit(3)"))
    with pytest.raises(WorkerFailed, match="ended with status 3"):
        broken.run(tmp_path, 1, ("bowl",), _rid(), 1.0)
    robot = MujocoRobot(data_dir=tmp_path, workers=1)
    robot._workers.close()
    robot._workers = broken
    try:
        rid = _rid()
        plan = robot.plan_execution("k", ("bowl",), rid.name)
        assert plan.trace[-1] == frozenset({"bowl"}) and viser_path(tmp_path, rid).exists()
    finally:
        robot.shutdown()
