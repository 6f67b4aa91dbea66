"""Executions worked out in the background: the start answers at once with a work_out job stored in its own
transaction; the plan is stored when the robot is ready and its clock starts then; a job whose process died, or
whose robot failed, is done again until it succeeds."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, Sequence
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest

from tableteach.db import jobs as job_rows
from tableteach.db.tables import JobRow, utcnow
from tableteach.robot import ExecutionPlan, TraceRobot
from tableteach.services import executions
from tableteach.services.runtime import WORK_OUT

from .conftest import in_process_app
from .helpers import bearer, demonstrate, make_study, to_teaching

WAIT = 60.0  # generous: the suite passes on a busy machine


class SlowRobot(TraceRobot):
    """A trace robot that, like the MuJoCo one, works executions out in the background, and only once the test
    lets it (or fails the first `failures` times)."""

    works_in_background = True

    def __init__(self, failures: int = 0) -> None:
        super().__init__("dinner", seconds_per_object=0.05)
        self.release_plans = threading.Event()
        self.worked: list[str] = []
        self.failures = failures

    def plan_execution(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> ExecutionPlan:
        self.worked.append(name)
        if self.failures > 0:
            self.failures -= 1
            raise RuntimeError("the robot failed to work the execution out")
        if not self.release_plans.wait(WAIT):
            raise RuntimeError("the test never let the plan through")
        return super().plan_execution(key, events, name, speed=speed)


@pytest.fixture
def slow_client(tmp_path: Path) -> Iterator[Any]:
    with in_process_app(tmp_path, SlowRobot()) as client:
        yield client


def _to_first_query(client: Any) -> str:
    study_id = make_study(client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    token, _ = to_teaching(client, study_id)
    demonstrate(client, token, ["dinner_plate", "fork"])
    return token


def _stored_execution(client: Any, token: str) -> dict[str, Any]:
    from tableteach.services.state import current_task, participant_and_study

    with client.ctx.db.read() as s:
        participant, _ = participant_and_study(s, token)
        return dict(current_task(s, participant).execution)


def _uid(client: Any, token: str) -> str:
    """The participant's random uid, which names their recordings."""
    from tableteach.services.state import participant_and_study

    with client.ctx.db.read() as s:
        return participant_and_study(s, token)[0].uid


def _until(condition: Any, what: str) -> None:
    deadline = time.monotonic() + WAIT
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.02)


def _pending(ctx: Any, kind: str) -> list[str]:
    """The stored jobs of one kind that are not done."""
    with ctx.db.read() as s:
        return [j.kind for j in job_rows.pending_jobs(s) if j.kind == kind]


def _finished(client: Any, token: str) -> dict[str, Any]:
    state: dict[str, Any] = {}

    def done() -> bool:
        state.update(client.get("/api/v1/me", headers=bearer(token)).json())
        return state["execution"]["status"] == "finished"

    _until(done, "the execution never finished")
    return state


def test_the_start_answers_before_the_plan_and_the_clock_starts_when_it_is_stored(slow_client) -> None:
    token = _to_first_query(slow_client)
    robot: SlowRobot = slow_client.ctx.robot
    started = slow_client.post("/api/v1/me/execution", headers=bearer(token))
    assert started.status_code == 200 and started.json()["execution"]["status"] == "running"
    stored = _stored_execution(slow_client, token)
    assert stored["plan"] is None and stored["recorded"]
    _until(lambda: robot.worked, "no work_out job ran")
    assert robot.worked[-1] == f"participant-{_uid(slow_client, token)}/task-0/query-0"
    activity = slow_client.get("/api/v1/me/robot", headers=bearer(token)).json()
    assert activity["moving"] and activity["caption"] == executions.GETTING_READY
    time.sleep(0.3)  # longer than the whole execution would take: without a plan it must not finish
    assert slow_client.get("/api/v1/me", headers=bearer(token)).json()["execution"]["status"] == "running"

    robot.release_plans.set()
    _until(lambda: _stored_execution(slow_client, token)["plan"] is not None,
           "the plan worked out in the background was never stored")
    state = _finished(slow_client, token)
    assert state["execution"]["trace"][-1] == sorted(state["execution"]["events"])
    _until(lambda: _stored_execution(slow_client, token)["status"] == "finished",
           "the runtime never recorded the finish (finish_execution job)")


def test_a_robot_that_fails_is_asked_again_until_the_plan_is_stored(tmp_path: Path) -> None:
    robot = SlowRobot(failures=2)
    robot.release_plans.set()
    with in_process_app(tmp_path, robot) as client:
        token = _to_first_query(client)
        assert client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
        _until(lambda: _stored_execution(client, token)["plan"] is not None, "the failed job was never retried")
        assert len([n for n in robot.worked if n.endswith("query-0")]) == 3  # two failures, then the plan
        _finished(client, token)


def test_a_job_whose_process_died_is_taken_over_once_its_lease_runs_out(slow_client) -> None:
    token = _to_first_query(slow_client)
    ctx = slow_client.ctx
    ctx.runtime.stop()  # this "process" stops taking jobs: the work_out job stays stored
    assert slow_client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
    with ctx.db.write() as s:  # as if a process had claimed it and died: its lease has run out
        job = s.query(JobRow).filter(JobRow.kind == WORK_OUT).one()
        job.claimed_by, job.claimed_until = "dead-process", utcnow() - timedelta(seconds=1)
        s.commit()
    from tableteach.services.context import Context, default_runtime

    other_robot = SlowRobot()
    other_robot.release_plans.set()
    other = Context(ctx.db, other_robot, ctx.settings, notifier=ctx.notifier, runtime=default_runtime())
    other.runtime.sweep_seconds = 0
    other.runtime.start(other)
    try:
        _until(lambda: _stored_execution(slow_client, token)["plan"] is not None,
               "the second process did not take the execution over")
        # the job's end is recorded in its own transaction just after the plan's: wait for it, then check once
        _until(lambda: not _pending(ctx, WORK_OUT), "the taken-over job was never recorded as done")
        assert other_robot.worked == [f"participant-{_uid(slow_client, token)}/task-0/query-0"]
    finally:
        other.runtime.stop()


def test_a_placement_settles_while_every_execution_waits_for_the_robot(slow_client) -> None:
    # Two participants' executions wait for the robot (their plans made ahead, their work-outs): before quick jobs
    # had runners of their own, a third participant's placement then waited behind them.
    study_id = make_study(slow_client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    for _ in range(2):
        token, _ = to_teaching(slow_client, study_id)
        demonstrate(slow_client, token, ["dinner_plate", "fork"])
        assert slow_client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
    robot = slow_client.ctx.robot
    _until(lambda: robot.worked, "the robot was never asked for an execution")
    placing, _ = to_teaching(slow_client, study_id)
    r = slow_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(placing))
    assert r.status_code == 200 and r.json()["demonstration"]["placed"] == ["bowl"]
    _until(lambda: slow_client.get("/api/v1/me", headers=bearer(placing)).json()["demonstration"]["settled"],
           "the placement did not settle while the executions waited for the robot")
    assert not robot.release_plans.is_set() and len(_pending(slow_client.ctx, WORK_OUT)) >= 1
    robot.release_plans.set()
