"""Planning ahead: robot turns are planned off the request path, once, and exactly as a request would."""

from __future__ import annotations

import threading
import time
from typing import Any

from tableteach.core import session as core
from tableteach.services.planning import PLANNER_THREAD, Planner, step_of

from tests.waiting import wait_until

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


def test_a_robot_turn_is_planned_on_the_planner_thread_and_once() -> None:
    state_json = _state_at_first_query().to_json()
    plan = RecordingPlan(seconds=0.3)
    planner = Planner(plan)
    try:
        planner.plan_ahead(state_json)
        planner.plan_ahead(state_json)  # already under way: not planned twice
        step = planner.step(state_json)  # waits for the plan being made
        assert [c[0] for c in plan.calls] == [state_json]
        assert plan.calls[0][1].startswith(PLANNER_THREAD)
        assert step.kind == "query" and step.robot_execution is not None
    finally:
        planner.shutdown()


def test_states_without_a_robot_turn_are_not_planned_ahead() -> None:
    config = core.SessionConfig(task="dinner", prior="chains-2020-sat", protocol="active", n_practice=1,
                                n_demonstrations=1, n_queries=1, n_tests=0, seed=1)
    plan = RecordingPlan()
    planner = Planner(plan)
    try:
        state_json = core.start(config).to_json()  # a practice trial comes next
        planner.plan_ahead(state_json)
        assert plan.calls == [] and state_json not in planner._plans  # decided before anything is submitted
    finally:
        planner.shutdown()


def test_the_plan_made_ahead_is_the_plan_a_request_would_make() -> None:
    state_json = _state_at_first_query(seed=11).to_json()
    planner = Planner()
    try:
        planner.plan_ahead(state_json)
        ahead = planner.step(state_json)
    finally:
        planner.shutdown()
    # A fresh state object and cleared caches: the plan is recomputed from nothing.
    core.next_step.cache_clear()
    fresh = core.next_step(core.SessionState.from_json(state_json))
    assert ahead.robot_execution is not None and fresh.robot_execution is not None
    assert ahead.robot_execution.events == fresh.robot_execution.events
    assert ahead.p_acceptable == fresh.p_acceptable


def test_a_failed_plan_ahead_is_made_again_in_the_request() -> None:
    state_json = _state_at_first_query().to_json()
    attempts: list[str] = []

    def flaky(js: str) -> core.Step:
        attempts.append(threading.current_thread().name)
        if len(attempts) == 1:
            raise RuntimeError("planning failed")
        return step_of(js)

    planner = Planner(flaky)
    try:
        planner.plan_ahead(state_json)
        step = planner.step(state_json)
        assert step.robot_execution is not None
        assert len(attempts) == 2 and attempts[0].startswith(PLANNER_THREAD)
        assert not attempts[1].startswith(PLANNER_THREAD)
    finally:
        planner.shutdown()


def test_the_server_plans_the_query_while_the_participant_reads_and_the_execution_uses_that_plan(
    app_client: Any,
) -> None:
    plan = RecordingPlan()
    app_client.ctx.planner.shutdown()
    app_client.ctx.planner = Planner(plan)
    token, state = to_teaching(app_client, make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=2))
    assert state["step"]["kind"] == "demonstration"
    state = demonstrate(app_client, token, ["dinner_plate", "small_plate"])
    assert state["step"]["kind"] == "query" and state["execution"]["status"] == "not_started"
    wait_until(lambda: plan.calls, "the planner to start planning the query ahead")
    assert len(plan.calls) == 1 and plan.calls[0][1].startswith(PLANNER_THREAD)
    response = app_client.post("/api/v1/me/execution", headers=bearer(token))
    assert response.status_code == 200, response.text
    planned = step_of(plan.calls[0][0])
    assert response.json()["execution"]["events"] == list(planned.robot_execution.events)
    assert len(plan.calls) == 1  # the request used the plan made ahead


def test_planning_ahead_never_fails_the_action_that_stored_the_state() -> None:
    planner = Planner()
    try:
        planner.plan_ahead("{not a session")  # logged, not raised: the action was already committed
    finally:
        planner.shutdown()
