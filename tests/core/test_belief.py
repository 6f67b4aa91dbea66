"""Exact posterior: against a naive per-hypothesis loop that uses general LTL evaluation."""

import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from tableteach.core.belief import Belief, LabelledExecution, log_likelihood
from tableteach.core.hypotheses import build_space, get_space
from tableteach.core.ltl_semantics import evaluate
from tableteach.core.metrics import similarity, similarities

from .strategies import small_domain, traces

SMALL = build_space(small_domain(), "chains-2020")


def naive_posterior(space, data):
    """Per-hypothesis loop with the spec's likelihood and textbook LTLf evaluation."""
    eps = math.exp(space.log_epsilon)
    weights = []
    for mask, log_prior in zip(space.masks, space.log_prior, strict=True):
        formula = space.domain.clause_space.formula_of(int(mask))
        n = bin(int(mask)).count("1")
        w = math.exp(log_prior)
        for trace, acceptable in data:
            sat = evaluate(formula, trace)
            if acceptable:
                w *= 2.0**n if sat else eps
            else:
                w *= (2.0**n / (2.0**n - 1)) if (not sat and n > 0) else eps
        weights.append(w)
    weights = np.array(weights)
    return weights / weights.sum()


labelled = st.lists(st.tuples(traces(), st.booleans()), min_size=0, max_size=4)


@given(labelled)
def test_posterior_equals_naive_loop(data):
    belief = Belief.prior(SMALL)
    for trace, acceptable in data:
        belief = belief.observe(trace, acceptable)
    np.testing.assert_allclose(belief.probs, naive_posterior(SMALL, data), atol=1e-9, rtol=0)


@given(labelled, traces())
def test_p_acceptable_equals_naive_sum(data, trace):
    belief = Belief.prior(SMALL).observe_all([LabelledExecution.of(t, a) for t, a in data])
    naive = sum(p for mask, p in zip(SMALL.masks, belief.probs, strict=True)
                if evaluate(SMALL.domain.clause_space.formula_of(int(mask)), trace))
    assert belief.p_acceptable(trace) == pytest.approx(naive, abs=1e-12)


@given(labelled, st.randoms(use_true_random=False))
def test_incremental_updates_equal_one_pass_from_scratch_in_any_order(data, random):
    step = Belief.prior(SMALL)
    for t, a in data:
        step = step.observe(t, a)
    cs = SMALL.domain.clause_space
    from_scratch = SMALL.log_prior + sum(
        (log_likelihood(SMALL, cs.sat_mask(t), a) for t, a in data), np.zeros(SMALL.size)
    )
    np.testing.assert_allclose(step.log_weights, from_scratch, rtol=0, atol=1e-9)
    shuffled = list(data)
    random.shuffle(shuffled)
    reordered = Belief.prior(SMALL).observe_all([LabelledExecution.of(t, a) for t, a in shuffled])
    np.testing.assert_allclose(reordered.probs, step.probs, rtol=0, atol=1e-12)


def test_likelihood_values_follow_the_spec():
    cs = SMALL.domain.clause_space
    trace = [frozenset(), frozenset({"a"}), frozenset({"a", "b"})]
    sat = cs.sat_mask(trace)
    acc = log_likelihood(SMALL, sat, True)
    rej = log_likelihood(SMALL, sat, False)
    for i, mask in enumerate(SMALL.masks):
        n = bin(int(mask)).count("1")
        ok = (int(mask) & ~sat) == 0
        assert acc[i] == pytest.approx(n * math.log(2) if ok else SMALL.log_epsilon)
        if ok or n == 0:
            assert rej[i] == pytest.approx(SMALL.log_epsilon)
        else:
            assert rej[i] == pytest.approx(math.log(2.0**n / (2.0**n - 1)))


def test_entropy_map_and_top_k():
    belief = Belief.prior(SMALL).observe([frozenset(), frozenset({"b"}), frozenset({"a", "b"})], True)
    p = belief.probs
    assert belief.entropy == pytest.approx(float(-(p * np.log(p)).sum()))
    top = belief.top(5)
    assert top[0][0] == belief.map_mask and top[0][1] == pytest.approx(p.max())
    assert [q for _, q in top] == sorted((q for _, q in top), reverse=True)
    assert sorted(p, reverse=True)[:5] == pytest.approx([q for _, q in top])


def test_similarity_vectorised_equals_scalar():
    cs = SMALL.domain.clause_space
    truth = cs.mask_of_formula("F(a) & (!b U a) & G(!c)")
    sims = similarities(SMALL, truth)
    for mask, s in zip(SMALL.masks[::7], sims[::7], strict=True):
        assert s == pytest.approx(similarity(cs, int(mask), truth))
    assert similarity(cs, truth, truth) == 1.0


def test_belief_similarity_is_an_expectation():
    belief = Belief.prior(SMALL).observe([frozenset(), frozenset({"a"})], True)
    truth = SMALL.domain.clause_space.mask_of_formula("F(a)")
    cs = SMALL.domain.clause_space
    naive = sum(float(p) * similarity(cs, int(mask), truth) for mask, p in zip(SMALL.masks, belief.probs, strict=True))
    assert belief.similarity(truth) == pytest.approx(naive)


def test_dinner_posterior_after_two_demos_is_concentrated_on_consistent_formulas():
    space = get_space("dinner", "chains-2020")
    demo = [frozenset(), frozenset({"dinner_plate"}), frozenset({"dinner_plate", "bowl"})]
    belief = Belief.prior(space).observe(demo, True).observe(demo, True)
    consistent = space.satisfied_by(space.domain.clause_space.sat_mask(demo))
    assert belief.probs[~consistent].sum() < 1e-20
    assert belief.p_acceptable(demo) == pytest.approx(1.0)


def test_bad_labels_and_traces_are_refused():
    with pytest.raises(ValueError, match="label must be true or false"):
        LabelledExecution.of([[]], "yes")
    with pytest.raises(ValueError, match="at least one state"):
        Belief.prior(SMALL).observe([], True)
    with pytest.raises(ValueError, match="unknown proposition"):
        Belief.prior(SMALL).observe([frozenset({"spoon"})], True)
