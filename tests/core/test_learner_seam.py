"""The learner seam: up to five objects the enumerating learner answers exactly as before; forced onto the exact path,
a four- or five-object task gets the same numbers to 1e-9; past five the exact learner answers and refuses by name
what it does not offer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tableteach.core import learner_seam as seam
from tableteach.core import session as core
from tableteach.core.clauses import MAX_CLAUSES
from tableteach.core.consistency import session_verdict_probabilities
from tableteach.core.domain import get_domain, objects_task
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import build_space
from tableteach.core.puns import node_acceptance
from tableteach.core.queries import plan_execution, query

FOUR = objects_task(("cup", "plate", "fork", "napkin"))


def _random_data(task: str, seed: int, n: int) -> core.Verdicts:
    """n labelled executions: two demonstrations of a fixed order, then random executions with random verdicts."""
    domain = get_domain(task)
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        order = list(domain.propositions)
        rng.shuffle(order)
        events = tuple(order[: int(rng.integers(0, len(order) + 1))])
        if k < 2:
            events = tuple(domain.propositions[:3]) if k == 0 else tuple(domain.propositions[1::-1]) + events[:1]
            events = tuple(dict.fromkeys(events))
        trace = tuple(domain.trace_of(events))
        out.append((trace, k < 2 or bool(rng.integers(2)), k >= 2))
    return tuple(out)


@pytest.mark.parametrize("task,prior", [("dinner", "chains-2020-sat"), ("dinner", "chains-2019"),
                                        (FOUR, "chains-2020-sat"), (FOUR, "total-order")])
def test_the_exact_path_agrees_with_the_enumerating_learner_to_1e_9(task: str, prior: str) -> None:
    domain = get_domain(task)
    space = domain.clause_space
    truth = space.mask_of_formula(f"F({domain.orderable[0]}) & (!{domain.orderable[1]} U {domain.orderable[0]})")
    graph = execution_graph(domain)
    for seed in range(2):
        data = _random_data(task, seed, 5)
        for k in range(len(data) + 1):
            enumerated = seam.belief_after(task, prior, 0.0, data[:k], "enumerating")
            exact = seam.belief_after(task, prior, 0.0, data[:k], "exact")
            assert (enumerated.path, exact.path) == ("enumerating", "exact")
            assert math.isclose(enumerated.entropy, exact.entropy, abs_tol=1e-9)
            assert math.isclose(enumerated.similarity(truth), exact.similarity(truth), abs_tol=1e-9)
            assert math.isclose(enumerated.map_probability, exact.map_probability, abs_tol=1e-9)
            # The exact MAP is a MAP of the enumerated belief (ties may pick another one).
            found = enumerated.belief.probs[enumerated.belief.space.find(exact.map_mask)]
            assert math.isclose(found, enumerated.map_probability, abs_tol=1e-9)
            assert exact.top(5) == [(exact.map_mask, exact.map_probability)] and len(enumerated.top(5)) == 5
            e_marg, x_marg = enumerated.marginals(), exact.marginals()
            assert e_marg.keys() == x_marg.keys()
            assert all(math.isclose(e_marg[c], x_marg[c], abs_tol=1e-9) for c in e_marg)
            for node in range(0, len(graph.events), max(1, len(graph.events) // 25)):
                trace = tuple(domain.trace_of(graph.events[node]))
                assert math.isclose(enumerated.p_acceptable(trace), exact.p_acceptable(trace), abs_tol=1e-9)
            # The robot's turns on the exact path: the plan is the enumerated optimum, the query's P is exact.
            rng = np.random.default_rng(k)
            plan, p_plan = seam.robot_plan(task, prior, 0.0, data[:k], "min-regret", rng, "exact")
            assert math.isclose(p_plan, float(node_acceptance(enumerated.belief).max()), abs_tol=1e-9)
            assert math.isclose(p_plan, enumerated.p_acceptable(plan.trace), abs_tol=1e-9)
            asked, p_query = seam.robot_query(task, prior, 0.0, data[:k], "active", rng, "exact")
            assert math.isclose(p_query, enumerated.p_acceptable(asked.trace), abs_tol=1e-9)


def test_up_to_five_objects_the_seam_gives_the_enumerating_learners_own_answers() -> None:
    data = _random_data("dinner", 3, 4)
    for k in range(len(data) + 1):
        belief = core.noisy_belief_after("dinner", "chains-2020-sat", 0.0, data[:k])
        seen = seam.belief_after("dinner", "chains-2020-sat", 0.0, data[:k])
        assert seen.path == "enumerating" and seen.belief is belief  # type: ignore[attr-defined]
        for strategy in ("active", "random"):
            assert seam.robot_query("dinner", "chains-2020-sat", 0.0, data[:k], strategy, np.random.default_rng(9)) \
                == query(belief, strategy, np.random.default_rng(9))
        assert seam.robot_plan("dinner", "chains-2020-sat", 0.0, data[:k], "most-likely", np.random.default_rng(2)) \
            == plan_execution(belief, "most-likely", np.random.default_rng(2))


def test_past_five_objects_the_exact_learner_answers_and_refuses_what_it_lacks_by_name() -> None:
    names = tuple(f"item{i}" for i in range(7))
    task = objects_task(names)
    assert seam.path_of(task) == "exact" and seam.path_of(FOUR) == "enumerating"
    domain = get_domain(task)
    assert domain.clause_space.n_clauses == 7 + 7 + 42
    state = core.start(core.SessionConfig(task=task, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=1))
    state = core.observe(state, "demonstration", domain.trace_of(("item0", "item1")))
    step = core.next_step(state)
    assert step.kind == "query" and step.robot_execution is not None and 0.0 <= (step.p_acceptable or 0) <= 1
    state = core.observe(state, "query", step.robot_execution.trace, False)
    learning, tests = session_verdict_probabilities(state)
    before = seam.belief_after(task, state.config.prior, 0.0, core.learning_verdicts(state)[:1])
    assert learning == [None, 1.0 - before.p_acceptable(step.robot_execution.trace)] and tests == []
    with pytest.raises(ValueError, match=r"noise-aware learner \(flip rate 0.1\) is not available past 5 objects"):
        seam.belief_after(task, "chains-2020-sat", 0.1, ())
    with pytest.raises(ValueError, match="criterion 'most-likely' is not available past 5 objects"):
        seam.robot_plan(task, "chains-2020-sat", 0.0, (), "most-likely", np.random.default_rng(0))
    assert [field for field, _ in seam.exact_problems("forest", 0.2, "most-coverage")] == [
        "prior", "flip_rate", "criterion"]
    assert seam.exact_problems("chains-2020-sat") == []
    with pytest.raises(ValueError, match="unknown learner path 'fast'"):
        seam.path_of(task, "fast")


def test_clause_spaces_past_63_clauses_hold_formulas_and_only_the_enumerated_learner_refuses_them() -> None:
    task = objects_task(tuple(f"o{i}" for i in range(10)))
    space = get_domain(task).clause_space
    assert space.n_clauses == 110 > MAX_CLAUSES
    formula = "G(!o9) & F(o0) & (!o8 U o7)"
    assert space.text_of(space.mask_of_formula(formula)) == formula
    with pytest.raises(ValueError, match="110 clauses do not fit a 64-bit mask"):
        build_space(get_domain(task), "chains-2020-sat")
    with pytest.raises(ValueError, match="110 clauses do not fit a 64-bit mask"):
        execution_graph(get_domain(task))
