"""Executions worked out in the background: the start answers at once, the plan is stored when the robot is
ready and its clock starts then; a plan that never comes (its process died) is worked out by a later request."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import Future
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest

from tableteach.robot import ExecutionPlan, TraceRobot
from tableteach.services import executions

from .conftest import in_process_app
from .helpers import bearer, demonstrate, make_study, to_teaching


class SlowRobot(TraceRobot):
    """A trace robot that, like the MuJoCo one, works executions out in the background (when the test says)."""

    def __init__(self) -> None:
        super().__init__("dinner", seconds_per_object=0.05)
        self.release_plans = threading.Event()
        self.prepared: list[str] = []

    def prepare(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> Future[ExecutionPlan]:
        future: Future[ExecutionPlan] = Future()
        self.prepared.append(name)
        if self.release_plans.is_set():  # worked out ahead: done by the time the execution starts
            future.set_result(self.plan_execution(key, events, name, speed=speed))
            return future

        def work() -> None:
            if self.release_plans.wait(10):
                future.set_result(self.plan_execution(key, events, name, speed=speed))
            else:
                future.set_exception(RuntimeError("the test never let the plan through"))

        threading.Thread(target=work, daemon=True).start()
        return future


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


def test_the_start_answers_before_the_plan_and_the_clock_starts_when_it_is_stored(slow_client) -> None:
    token = _to_first_query(slow_client)
    robot: SlowRobot = slow_client.ctx.robot
    started = slow_client.post("/api/v1/me/execution", headers=bearer(token))
    assert started.status_code == 200 and started.json()["execution"]["status"] == "running"
    stored = _stored_execution(slow_client, token)
    assert stored["plan"] is None and stored["recorded"]
    assert robot.prepared[-1] == f"participant-{_uid(slow_client, token)}/task-0/query-0"
    activity = slow_client.get("/api/v1/me/robot", headers=bearer(token)).json()
    assert activity["moving"] and activity["caption"] == executions.GETTING_READY
    time.sleep(0.3)  # longer than the whole execution would take: without a plan it must not finish
    assert slow_client.get("/api/v1/me", headers=bearer(token)).json()["execution"]["status"] == "running"

    robot.release_plans.set()
    deadline = time.monotonic() + 10
    while _stored_execution(slow_client, token)["plan"] is None:
        assert time.monotonic() < deadline, "the plan worked out in the background was never stored"
        time.sleep(0.02)
    state = slow_client.get("/api/v1/me", headers=bearer(token)).json()
    while state["execution"]["status"] != "finished":
        assert time.monotonic() < deadline
        time.sleep(0.02)
        state = slow_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["execution"]["trace"][-1] == sorted(state["execution"]["events"])


def test_a_plan_that_never_comes_is_worked_out_by_a_later_request(slow_client) -> None:
    token = _to_first_query(slow_client)
    assert slow_client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
    # As if the process working it out had died: the plan never comes, and the grace period has passed.
    stored = _stored_execution(slow_client, token)
    assert stored["plan"] is None
    from datetime import datetime

    from tableteach.services.state import current_task, participant_and_study

    long_ago = datetime.fromisoformat(stored["started_at"]) - timedelta(seconds=executions.PREPARE_GRACE_SECONDS + 1)
    with slow_client.ctx.db.write() as s:
        participant, _ = participant_and_study(s, token)
        ts = current_task(s, participant)
        ts.execution = {**ts.execution, "started_at": long_ago.isoformat()}
        s.commit()
    state = slow_client.get("/api/v1/me", headers=bearer(token)).json()
    assert _stored_execution(slow_client, token)["plan"] is not None  # worked out in that request
    deadline = time.monotonic() + 10
    while state["execution"]["status"] != "finished":
        assert time.monotonic() < deadline
        time.sleep(0.02)
        state = slow_client.get("/api/v1/me", headers=bearer(token)).json()
    slow_client.ctx.robot.release_plans.set()  # the late background plan must not overwrite the stored one
    time.sleep(0.2)
    assert _stored_execution(slow_client, token)["status"] == "finished"


def test_a_plan_made_ahead_is_stored_without_blocking_the_request_that_starts_it(slow_client) -> None:
    token = _to_first_query(slow_client)
    slow_client.ctx.robot.release_plans.set()  # prepare() now answers with a finished plan
    answers: list[Any] = []
    request = threading.Thread(target=lambda: answers.append(
        slow_client.post("/api/v1/me/execution", headers=bearer(token))), daemon=True)
    request.start()
    request.join(timeout=10)
    assert answers and answers[0].status_code == 200, "starting the execution hung"
    deadline = time.monotonic() + 10
    while _stored_execution(slow_client, token)["plan"] is None:
        assert time.monotonic() < deadline, "the plan made ahead was never stored"
        time.sleep(0.02)


def test_a_process_asked_about_an_execution_another_was_working_out_takes_it_over(slow_client) -> None:
    token = _to_first_query(slow_client)
    assert slow_client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
    assert _stored_execution(slow_client, token)["plan"] is None  # the first "process" never finishes it
    slow_client.ctx.robot = SlowRobot()  # another process, whose robot has never heard of the execution
    slow_client.ctx.robot.release_plans.set()
    state = slow_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["execution"]["status"] == "running"
    deadline = time.monotonic() + 5  # far sooner than the grace period
    while _stored_execution(slow_client, token)["plan"] is None:
        assert time.monotonic() < deadline, "the second process did not take the execution over"
        time.sleep(0.02)
    assert slow_client.ctx.robot.prepared == [f"participant-{_uid(slow_client, token)}/task-0/query-0"]
