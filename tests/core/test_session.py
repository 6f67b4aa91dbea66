"""Teaching-session state machine: protocol order, determinism, JSON round trip, errors."""

import numpy as np
import pytest

from tableteach.core.domain import get_domain
from tableteach.core.session import (
    ProtocolError, SessionConfig, SessionState, belief, beliefs_by_step, next_step, observe, position, start,
)
from tableteach.core.teachers import SimulatedTeacher

DINNER = get_domain("dinner")
TASK1 = DINNER.clause_space.mask_of_formula(
    "F(dinner_plate) & F(small_plate) & F(bowl) & F(knife) & F(fork) & (!small_plate U dinner_plate)"
    " & (!bowl U small_plate) & (!bowl U dinner_plate)"
)


def run(config: SessionConfig, teacher_seed: int = 0) -> tuple[SessionState, list[str]]:
    teacher = SimulatedTeacher(DINNER, TASK1)
    rng = np.random.default_rng(teacher_seed)
    state, kinds = start(config), []
    while (step := next_step(state)).kind != "done":
        kinds.append(step.kind)
        if step.robot_execution is None:
            state = observe(state, step.kind, teacher.demonstrate(rng).trace)
        else:
            trace = step.robot_execution.trace
            state = observe(state, step.kind, trace, teacher.assess(trace, rng))
    return state, kinds


@pytest.mark.parametrize("protocol, demos, queries", [("active", 2, 3), ("random", 2, 3), ("batch", 5, 0)])
def test_protocol_order_and_counts(protocol, demos, queries):
    state, kinds = run(SessionConfig(protocol=protocol, seed=1))
    expected = ["practice"] + ["demonstration"] * demos + ["query"] * queries + ["test"] * 3
    assert kinds == expected
    assert len(beliefs_by_step(state)) == 1 + demos + queries


def test_same_seed_same_session_and_json_round_trip():
    a, _ = run(SessionConfig(seed=5))
    b, _ = run(SessionConfig(seed=5))
    assert a == b
    again = SessionState.from_json(a.to_json())
    assert again == a
    np.testing.assert_array_equal(belief(again).probs, belief(a).probs)


def test_reloaded_session_proposes_the_same_next_query():
    state, _ = run(SessionConfig(seed=2, n_queries=0, n_tests=0))
    config = SessionConfig(seed=2)
    partial = SessionState(config, state.records)
    step = next_step(partial)
    reloaded = SessionState.from_json(partial.to_json())
    assert step.kind == "query"
    assert next_step(reloaded).robot_execution == step.robot_execution


def test_active_queries_are_recorded_with_what_the_robot_proposed():
    state, _ = run(SessionConfig(seed=3))
    queries = [r for r in state.records if r.kind == "query"]
    assert all(r.proposed is not None and isinstance(r.acceptable, bool) for r in queries)


def test_out_of_order_events_are_refused_with_what_was_expected():
    state = start(SessionConfig())
    with pytest.raises(ProtocolError, match="expects a practice"):
        observe(state, "query", [[]], True)
    state = observe(state, "practice", [[], ["fork"]])
    with pytest.raises(ProtocolError, match="acceptable by definition"):
        observe(state, "demonstration", [[]], False)
    with pytest.raises(ValueError, match="unknown proposition"):
        observe(state, "demonstration", [[], ["spoon"]])


def test_bad_configs_are_named():
    with pytest.raises(ValueError, match="unknown protocol"):
        SessionConfig(protocol="socratic")
    with pytest.raises(ValueError, match="n_queries must be a whole number"):
        SessionConfig(n_queries=-1)
    with pytest.raises(ValueError, match="malformed session JSON"):
        SessionState.from_json('{"schema": 1}')


def test_teacher_demonstration_modes():
    rng = np.random.default_rng(0)
    fixed = SimulatedTeacher(DINNER, TASK1, demo_mode="fixed")
    demos = {fixed.demonstrate(rng).events for _ in range(5)}
    assert len(demos) == 1  # the same demonstration every time
    varied = SimulatedTeacher(DINNER, TASK1, demo_mode="optimal")
    assert len({varied.demonstrate(rng).events for _ in range(20)}) > 5
    for mode in ("optimal", "uniform", "fixed"):
        teacher = SimulatedTeacher(DINNER, TASK1, demo_mode=mode)
        assert teacher.assess(teacher.demonstrate(rng).trace, rng)


@pytest.mark.parametrize("protocol, demos, queries", [("active", 2, 3), ("batch", 5, 0)])
def test_position_counts_through_each_phase(protocol, demos, queries):
    state, _ = run(SessionConfig(protocol=protocol, seed=4))  # 1 practice, 2 demonstrations, 3 queries, 3 tests
    expected = ([("practice", 0, 1)] + [("demonstration", i, demos) for i in range(demos)]
                + [("query", i, queries) for i in range(queries)] + [("test", i, 3) for i in range(3)]
                + [("done", 0, 0)])
    positions = [position(SessionState(state.config, state.records[:k])) for k in range(len(state.records) + 1)]
    assert positions == expected
