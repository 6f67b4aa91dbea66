"""PUnS planning and queries: worked example, brute force over all executions, value iteration."""

from itertools import permutations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tableteach.core.belief import Belief
from tableteach.core.domain import get_domain, synthetic_domain
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import explicit_space, get_space
from tableteach.core.ltl_semantics import accepts_at_end, nnf, progress
from tableteach.core.puns import RewardMachine, criterion_weights, solve
from tableteach.core.queries import active_query, plan_execution, random_query

DINNER = get_domain("dinner")
ALL_EXECUTIONS = [order for k in range(6) for order in permutations(DINNER.propositions, k)]


def worked_example() -> Belief:
    space = explicit_space(DINNER, {
        "G(!fork) & F(bowl) & (!bowl U dinner_plate)": 0.3,
        "G(!fork) & F(bowl)": 0.7,
    })
    return Belief.prior(space)


def test_paper_worked_example():
    belief = worked_example()
    plan, p = plan_execution(belief)
    assert plan.events == ("dinner_plate", "bowl") and p == pytest.approx(1.0)
    query, q = active_query(belief, ties="shortest")
    assert query.events == ("bowl",) and q == pytest.approx(0.7)
    tied = {e for e, p in zip(ALL_EXECUTIONS, brute_force_p(belief), strict=True) if p == pytest.approx(0.7)}
    rng = np.random.default_rng(0)
    drawn = {active_query(belief, rng)[0].events for _ in range(200)}  # uniform: any tied one, not only shortest
    assert drawn <= tied and len(drawn) > 10 and any(len(e) > 1 for e in drawn)
    with pytest.raises(ValueError, match="unknown query tie-breaking 'first'"):
        active_query(belief, rng, ties="first")


def brute_force_p(belief):
    return np.array([belief.p_acceptable(DINNER.trace_of(e)) for e in ALL_EXECUTIONS])


def random_belief(seed: int, prior: str = "chains-2020-sat") -> Belief:
    rng = np.random.default_rng(seed)
    belief = Belief.prior(get_space("dinner", prior))
    for _ in range(rng.integers(0, 4)):
        order = ALL_EXECUTIONS[rng.integers(len(ALL_EXECUTIONS))]
        belief = belief.observe(DINNER.trace_of(order), bool(rng.random() < 0.6))
    return belief


def test_there_are_326_dinner_executions():
    assert len(ALL_EXECUTIONS) == 326 == execution_graph(DINNER).n_nodes


@settings(max_examples=12)
@given(st.integers(0, 10_000))
def test_min_regret_plan_is_best_of_all_executions(seed):
    belief = random_belief(seed)
    plan, p = plan_execution(belief, rng=np.random.default_rng(seed))
    assert p == pytest.approx(brute_force_p(belief).max(), abs=1e-12)


@settings(max_examples=12)
@given(st.integers(0, 10_000), st.sampled_from(["uniform", "shortest", "stepwise", "uniform-executions"]))
def test_active_query_equals_brute_force(seed, ties):
    belief = random_belief(seed)
    query, q = active_query(belief, np.random.default_rng(seed), ties)
    score = np.abs(2 * brute_force_p(belief) - 1)
    best = score <= score.min() + 1e-12
    shortest = min(len(e) for e, b in zip(ALL_EXECUTIONS, best, strict=True) if b)
    allowed = {e for e, b in zip(ALL_EXECUTIONS, best, strict=True) if b and (ties != "shortest" or len(e) == shortest)}
    assert query.events in allowed
    assert abs(2 * q - 1) == pytest.approx(score.min(), abs=1e-12)


def test_plan_and_query_on_the_full_2020_space_match_brute_force():
    belief = random_belief(3, prior="chains-2020")
    p_all = brute_force_p(belief)
    _, p = plan_execution(belief)
    assert p == pytest.approx(p_all.max(), abs=1e-12)
    _, q = active_query(belief)
    assert abs(2 * q - 1) == pytest.approx(np.abs(2 * p_all - 1).min(), abs=1e-12)


def test_weighted_acceptance_equals_naive_sum():
    belief = random_belief(11)
    rng = np.random.default_rng(0)
    w = rng.random(belief.space.size)
    graph = execution_graph(DINNER)
    fast = belief.space.weighted_acceptance(w, graph.sat)
    naive = [w[belief.space.satisfied_by(int(s))].sum() for s in graph.sat]
    np.testing.assert_allclose(fast, naive, rtol=1e-10)


def test_reward_machine_tracks_clause_status():
    belief = worked_example()
    rm = RewardMachine(belief)
    cs = DINNER.clause_space
    for order in ALL_EXECUTIONS[::5]:
        trace = DINNER.trace_of(order)
        u = rm.initial()
        for labels in trace:
            u, reward, done = rm.step(u, labels)
        assert rm.final_mask(u) == cs.sat_mask(trace)
        assert rm.final_reward(u) == pytest.approx(2 * belief.p_acceptable(trace) - 1)
    u = rm.initial()
    for labels in DINNER.trace_of(("dinner_plate", "bowl")):
        u, reward, done = rm.step(u, labels)
    assert done and reward == pytest.approx(1.0)


def test_criteria():
    belief = random_belief(5)
    for name in ("min-regret", "most-likely", "most-coverage", "chance-constrained"):
        w = criterion_weights(belief, name)
        assert w.sum() == pytest.approx(1.0) and (w >= 0).all()
    w = criterion_weights(belief, "most-likely")
    assert w[belief.map_index] == 1.0
    plan, _ = plan_execution(belief, "most-likely")
    assert (belief.map_mask & ~DINNER.clause_space.sat_mask(plan.trace)) == 0
    np.testing.assert_allclose(criterion_weights(belief, "chance-constrained", risk=0.0), belief.probs, atol=1e-9)
    with pytest.raises(ValueError, match="unknown criterion"):
        criterion_weights(belief, "bravest")


def test_random_query_ends_and_places_each_object_once():
    belief = random_belief(1)
    rng = np.random.default_rng(4)
    lengths = set()
    for _ in range(50):
        execution, p = random_query(belief, rng)
        assert len(set(execution.events)) == len(execution.events)
        assert 0.0 <= p <= 1.0
        lengths.add(len(execution.events))
    assert len(lengths) > 2


def test_exact_planner_equals_value_iteration_on_the_stochastic_product():
    """Synthetic domain (moves fail w.p. 0.2): explicit product of positions and LTL residuals."""
    domain = synthetic_domain(3, 2)
    space = explicit_space(domain, {
        "F(w0) & F(w2) & (!w2 U w0) & G(!t0)": 0.5,
        "F(w1) & (!w0 U w1) & G(!t1)": 0.3,
        "F(w2) & G(!t0) & G(!t1)": 0.2,
    })
    belief = Belief.prior(space)
    formulas = [nnf(space.domain.clause_space.formula_of(int(m))) for m in space.masks]
    p = belief.probs

    def stop_reward(residuals):
        return sum(pi * (1 if accepts_at_end(r) else -1) for pi, r in zip(p, residuals, strict=True))

    start = (None, tuple(progress(f, frozenset()) for f in formulas))
    states, frontier = {start}, [start]
    while frontier:
        pos, res = frontier.pop()
        for loc in domain.propositions:
            nxt = (loc, tuple(progress(r, frozenset({loc})) for r in res))
            if nxt not in states:
                states.add(nxt)
                frontier.append(nxt)
    value = {s: stop_reward(s[1]) for s in states}
    for _ in range(500):
        for s in states:
            pos, res = s
            best = stop_reward(res)
            for loc in domain.propositions:
                nxt = (loc, tuple(progress(r, frozenset({loc})) for r in res))
                stay = (pos, tuple(progress(r, frozenset({pos}) if pos else frozenset()) for r in res))
                best = max(best, 0.8 * value[nxt] + 0.2 * value.get(stay, value[s]))
            value[s] = best
    policy = solve(belief)
    assert policy.value[0] == pytest.approx(value[start], abs=1e-6)
