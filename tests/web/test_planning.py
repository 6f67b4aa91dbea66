"""Planning ahead: robot turns are planned off the request path (a plan_ahead job), once, and exactly as a request
would."""

from __future__ import annotations

import threading
import time
from typing import Any

from tableteach.core import session as core
from tableteach.services.planning import Planner, step_of

from .helpers import bearer, demonstrate, make_study, to_teaching


def _state_at_first_query(seed: int = 7) -> core.SessionState:
    config = core.SessionConfig(task="dinner", prior="chains-2020-sat", protocol="active", n_practice=0,
                                n_demonstrations=1, n_queries=2, n_tests=1, seed=seed)
    trace = [[], ["dinner_plate"], ["dinner_plate", "small_plate"]]
    return core.observe(core.start(config), "demonstration", trace)


class RecordingPlan:
    """A plan function that records which thread planned which state, and can be slow."""

    def __init__(self, seconds: float = 0.0) -> None:
        self.seconds = seconds
        self.calls: list[tuple[str, str]] = []
        self.lock = threading.Lock()

    def __call__(self, state_json: str) -> core.Step:
        with self.lock:
            self.calls.append((state_json, threading.current_thread().name))
        time.sleep(self.seconds)
        return step_of(state_json)


def test_two_threads_asking_for_one_plan_make_it_once() -> None:
    state_json = _state_at_first_query().to_json()
    plan = RecordingPlan(seconds=0.3)
    planner = Planner(plan)
    steps: list[core.Step] = []
    threads = [threading.Thread(target=lambda: steps.append(planner.step(state_json))) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    assert [c[0] for c in plan.calls] == [state_json]
    assert len(steps) == 2 and steps[0] is steps[1] and steps[0].robot_execution is not None
    assert planner.planned(state_json)


def test_the_plan_made_ahead_is_the_plan_a_request_would_make() -> None:
    state_json = _state_at_first_query(seed=11).to_json()
    ahead = Planner().step(state_json)
    # A fresh state object and cleared caches: the plan is recomputed from nothing.
    core.next_step.cache_clear()
    fresh = core.next_step(core.SessionState.from_json(state_json))
    assert ahead.robot_execution is not None and fresh.robot_execution is not None
    assert ahead.robot_execution.events == fresh.robot_execution.events
    assert ahead.p_acceptable == fresh.p_acceptable


def test_a_failed_plan_is_made_again_by_the_next_caller() -> None:
    state_json = _state_at_first_query().to_json()
    attempts: list[str] = []

    def flaky(js: str) -> core.Step:
        attempts.append(js)
        if len(attempts) == 1:
            raise RuntimeError("planning failed")
        return step_of(js)

    planner = Planner(flaky)
    try:
        planner.step(state_json)
    except RuntimeError:
        pass
    assert not planner.planned(state_json)
    assert planner.step(state_json).robot_execution is not None and len(attempts) == 2


def test_the_server_plans_the_query_on_a_runtime_job_and_the_execution_uses_that_plan(app_client: Any) -> None:
    plan = RecordingPlan()
    app_client.ctx.planner = Planner(plan)
    token, state = to_teaching(app_client, make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=2))
    assert state["step"]["kind"] == "demonstration"
    state = demonstrate(app_client, token, ["dinner_plate", "small_plate"])
    assert state["step"]["kind"] == "query" and state["execution"]["status"] == "not_started"
    deadline = time.monotonic() + 60
    while not plan.calls and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(plan.calls) == 1 and plan.calls[0][1].startswith("runtime-jobs")
    response = app_client.post("/api/v1/me/execution", headers=bearer(token))
    assert response.status_code == 200, response.text
    planned = step_of(plan.calls[0][0])
    assert response.json()["execution"]["events"] == list(planned.robot_execution.events)
    assert len(plan.calls) == 1  # the request used the plan made ahead


def test_a_plan_ahead_job_for_a_broken_state_is_retried_not_fatal(app_client: Any) -> None:
    """A job whose handler fails stays stored and is tried again; the action that wrote it had committed."""
    from tableteach.db import jobs as job_rows
    from tableteach.services.runtime import PLAN_AHEAD

    token, _state = to_teaching(app_client, make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=1))
    ctx = app_client.ctx
    pid = app_client.get("/api/v1/me", headers=bearer(token)).json()["participant_id"]
    failures = ctx.runtime.failed_count
    ctx.runtime.handlers = {**ctx.runtime.handlers, PLAN_AHEAD: _broken}
    with ctx.db.write() as s:
        job_rows.add_job(s, kind=PLAN_AHEAD, participant_id=pid, task_index=0, payload={"state": "{not a session"})
        s.commit()
    ctx.runtime.wake()
    deadline = time.monotonic() + 60
    while ctx.runtime.failed_count < failures + 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert ctx.runtime.failed_count >= failures + 2  # tried, failed, tried again after its backoff
    with ctx.db.read() as s:
        (job,) = [j for j in job_rows.pending_jobs(s, participant_id=pid) if j.kind == PLAN_AHEAD]
        assert job.attempts >= 2 and "planning failed" in (job.last_error or "")


def _broken(_ctx: Any, _job: Any) -> None:
    raise RuntimeError("planning failed")
