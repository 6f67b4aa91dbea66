"""Teacher consistency: each verdict's probability just before it was given, the score and the AUC."""

import numpy as np
import pytest

from tableteach.core import session as core
from tableteach.core.consistency import auc, consistency_score, session_verdict_probabilities, verdict_probabilities
from tableteach.core.belief import Belief
from tableteach.core.hypotheses import get_space

DEMO = [[], ["dinner_plate"], ["dinner_plate", "bowl"]]


def test_each_verdict_gets_the_probability_of_the_belief_before_it():
    config = core.SessionConfig(protocol="random", n_practice=0, n_demonstrations=1, n_queries=2, n_tests=1, seed=4)
    state = core.observe(core.start(config), "demonstration", DEMO)
    verdicts = []
    for kind, acceptable in (("query", True), ("query", False), ("test", False)):
        trace = core.next_step(state).robot_execution.trace
        state = core.observe(state, kind, [sorted(s) for s in trace], acceptable)
        verdicts.append((trace, acceptable))
    learning, tests = session_verdict_probabilities(state)
    belief = Belief.prior(get_space("dinner", config.prior)).observe(DEMO, True)
    p1 = belief.p_acceptable(verdicts[0][0])
    belief = belief.observe(verdicts[0][0], True)
    p2 = 1 - belief.p_acceptable(verdicts[1][0])
    belief = belief.observe(verdicts[1][0], False)
    p3 = 1 - belief.p_acceptable(verdicts[2][0])
    assert learning[0] is None and learning[1:] == pytest.approx([p1, p2], abs=1e-12)
    assert tests == pytest.approx([p3], abs=1e-12)
    assert consistency_score([*learning, *tests]) == pytest.approx((p1 + p2 + p3) / 3)
    prior = Belief.prior(get_space("dinner", config.prior))
    data = [(tuple(map(frozenset, DEMO)), True, False), (verdicts[0][0], True, True), (verdicts[1][0], False, True)]
    assert verdict_probabilities(prior, data) == pytest.approx([None, p1, p2])


def test_a_verdict_against_the_demonstrations_is_improbable():
    prior = Belief.prior(get_space("dinner", "chains-2020-sat"))
    demo = tuple(map(frozenset, DEMO))
    agree, disagree = verdict_probabilities(prior, [(demo, True, False), (demo, True, True)])[1], \
        verdict_probabilities(prior, [(demo, True, False), (demo, False, True)])[1]
    assert agree > 0.99 and disagree < 0.01


def test_auc_counts_pairs_and_half_ties():
    assert auc([3, 4], [1, 2]) == 1.0
    assert auc([1, 2], [3, 4]) == 0.0
    assert auc([1, 3], [1, 2]) == pytest.approx((0.5 + 0 + 1 + 1) / 4)
    assert consistency_score([None, None]) is None
    with pytest.raises(ValueError, match="at least one score in each group"):
        auc([], [1.0])
    assert auc(np.ones(3), np.ones(2)) == 0.5
