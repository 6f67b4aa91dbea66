"""The noise-aware learner (verdict-flip likelihood) and the information-gain query, against naive loops."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tableteach.core.belief import Belief, check_flip_rate, log_likelihood
from tableteach.core.domain import DINNER_TASK_FORMULAS
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import build_space, get_space
from tableteach.core.ltl_semantics import evaluate
from tableteach.core import session as core
from tableteach.core.queries import expected_information_gain, information_gain_query

from .strategies import small_domain, traces

SMALL = build_space(small_domain(), "chains-2020")
labelled = st.lists(st.tuples(traces(), st.booleans()), min_size=0, max_size=4)


def naive_noisy_posterior(space, data, f):
    """Per-hypothesis loop: an agreeing verdict keeps the authors' term times (1 - f), a contradicted one gets f."""
    weights = []
    for mask, log_prior in zip(space.masks, space.log_prior, strict=True):
        formula = space.domain.clause_space.formula_of(int(mask))
        n = bin(int(mask)).count("1")
        w = math.exp(log_prior)
        for trace, acceptable in data:
            sat = evaluate(formula, trace)
            if acceptable:
                w *= (1 - f) * 2.0**n if sat else f
            else:
                w *= (1 - f) * 2.0**n / (2.0**n - 1) if not sat else f
        weights.append(w)
    weights = np.array(weights)
    return weights / weights.sum()


@given(labelled, st.sampled_from([0.05, 0.1, 0.3]))
@settings(max_examples=30, deadline=None)
def test_noisy_posterior_equals_naive_loop(data, f):
    belief = Belief.prior(SMALL)
    for trace, acceptable in data:
        belief = belief.observe(trace, acceptable, f)
    assert np.allclose(belief.probs, naive_noisy_posterior(SMALL, data, f), rtol=1e-9, atol=1e-12)


@given(traces(), st.booleans())
def test_flip_rate_zero_is_the_authors_likelihood_bit_for_bit(trace, acceptable):
    mask = SMALL.domain.clause_space.sat_mask(trace)
    satisfied = SMALL.satisfied_by(mask)
    expected = (np.where(satisfied, SMALL.ll_satisfied, SMALL.log_epsilon) if acceptable
                else np.where(satisfied, SMALL.log_epsilon, SMALL.ll_violated))
    assert np.array_equal(log_likelihood(SMALL, mask, acceptable, 0.0), expected)
    assert np.array_equal(Belief.prior(SMALL).observe(trace, acceptable).log_weights,
                          Belief.prior(SMALL).observe(trace, acceptable, 0.0).log_weights)


def test_one_wrong_verdict_no_longer_rules_out_the_truth():
    space = get_space("dinner", "chains-2020-sat")
    domain = space.domain
    truth = domain.clause_space.mask_of_formula(DINNER_TASK_FORMULAS["task2"])
    demo = [frozenset(), frozenset({"dinner_plate"}), frozenset({"dinner_plate", "bowl"})]
    for f in (0.0, 0.1):
        longer = [*demo, frozenset({"dinner_plate", "bowl", "fork"})]  # satisfies the truth too
        belief = Belief.prior(space).observe(demo, True).observe(longer, False, f)  # a flipped verdict
        p_truth = float(belief.probs[space.find(truth)])
        if f == 0.0:
            assert p_truth < 1e-15  # the authors' learner: epsilon, the truth is ruled out
        else:
            assert p_truth > 1e-4


@pytest.mark.parametrize("bad", [-0.1, 0.5, 0.7, True, "0.1", float("nan")])
def test_flip_rates_outside_zero_to_a_half_are_refused(bad):
    with pytest.raises(ValueError, match=r"flip rate must be a probability in \[0, 0.5\)"):
        check_flip_rate(bad)
    with pytest.raises(ValueError, match="flip_rate"):
        core.SessionConfig(flip_rate=bad)


def test_a_session_with_a_flip_rate_learns_demonstrations_as_certain_and_verdicts_as_noisy():
    config = core.SessionConfig(protocol="active", n_practice=0, n_demonstrations=1, n_queries=1, flip_rate=0.2)
    state = core.start(config)
    demo = [[], ["dinner_plate"], ["dinner_plate", "bowl"]]
    state = core.observe(state, "demonstration", demo)
    query = core.next_step(state).robot_execution
    state = core.observe(state, "query", [sorted(s) for s in query.trace], False)
    space = get_space("dinner", config.prior)
    expected = Belief.prior(space).observe(demo, True).observe(query.trace, False, 0.2)
    assert np.array_equal(core.belief(state).log_weights, expected.log_weights)
    assert np.array_equal(core.beliefs_by_step(state)[-1].log_weights, expected.log_weights)
    again = core.SessionState.from_json(state.to_json())
    assert again.config.flip_rate == 0.2 and np.array_equal(core.belief(again).log_weights, expected.log_weights)


def test_sessions_of_the_authors_learner_store_the_same_json_as_before():
    state = core.start(core.SessionConfig())
    assert "flip_rate" not in state.to_json()
    assert core.SessionState.from_json(state.to_json()).config.flip_rate == 0.0


def naive_gain(belief, sat_mask, f):
    """Prior entropy minus the expected posterior entropy, by building both posteriors."""
    p_sat = belief.p_acceptable_mask(sat_mask)
    p_acc = (1 - f) * p_sat + f * (1 - p_sat)
    out = belief.entropy
    for acceptable, p in ((True, p_acc), (False, 1 - p_acc)):
        out -= p * belief.observe_mask(sat_mask, acceptable, f).entropy
    return out


@given(labelled, st.sampled_from([0.0, 0.1]))
@settings(max_examples=20, deadline=None)
def test_information_gain_equals_entropy_of_each_posterior(data, f):
    belief = Belief.prior(SMALL)
    for trace, acceptable in data:
        belief = belief.observe(trace, acceptable, f)
    sat = execution_graph(SMALL.domain).sat
    gains = expected_information_gain(belief, sat, f)
    naive = np.array([naive_gain(belief, int(m), f) for m in sat])
    assert np.allclose(gains, naive, atol=1e-9)


def test_information_gain_query_picks_a_most_informative_execution():
    space = get_space("synthetic", "chains-2020-sat")
    belief = Belief.prior(space).observe([frozenset(), frozenset({"w0"}), frozenset({"w0", "w1"})], True)
    graph = execution_graph(space.domain)
    gains = expected_information_gain(belief, graph.sat)
    execution, p = information_gain_query(belief, np.random.default_rng(1))
    mask = space.domain.clause_space.sat_mask(execution.trace)
    assert naive_gain(belief, mask, 0.0) == pytest.approx(gains.max(), abs=1e-8)
    assert p == pytest.approx(belief.p_acceptable(execution.trace))
