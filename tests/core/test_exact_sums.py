"""The fast paths of the learner give bitwise the same numbers as the plain formulas they replace.

weighted_acceptance (a zeta transform over the needed codes, blocks and groups of executions), satisfied_by
on block-laid-out spaces and the belief's in-place summaries must not move a result by one rounding: a
query or a plan decided on a tie, and a sweep's output, would change with it.
"""

import numpy as np
import pytest

from tableteach.core.belief import Belief, log_likelihood
from tableteach.core.domain import get_domain
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import HypothesisSpace, explicit_space, get_space

SPACES = [("dinner", "chains-2020-sat"), ("dinner", "chains-2020"), ("synthetic", "chains-2020-sat")]


def reference_acceptance(space: HypothesisSpace, weights: np.ndarray, sat_masks: np.ndarray) -> np.ndarray:
    """sum_h w_h [e satisfies h] as first written: the whole (pattern x code) table, pairs pattern by pattern."""
    k = space.n_unary
    n_patterns = space.u_patterns.size
    cells = (space.u_index << k) + space.unary_code
    table = np.bincount(cells, weights=weights, minlength=n_patterns << k).reshape(n_patterns, 1 << k)
    for bit in range(k):
        view = table.reshape(n_patterns, 1 << (k - 1 - bit), 2, 1 << bit)
        view[:, :, 1, :] += view[:, :, 0, :]
    order_sat = sat_masks & ~np.uint64((1 << k) - 1)
    pattern, execution = np.nonzero((space.u_patterns[:, None] & ~order_sat[None, :]) == 0)
    codes = (sat_masks & np.uint64((1 << k) - 1)).astype(np.int64)
    flat = (pattern.astype(np.int64) << k) + codes[execution]
    return np.bincount(execution, weights=table.ravel()[flat], minlength=sat_masks.size)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def weight_cases(size: int, rng: np.random.Generator) -> list[np.ndarray]:
    spread = rng.random(size) * np.exp(rng.normal(0.0, 20.0, size))  # many magnitudes: rounding shows
    holes = spread.copy()
    holes[rng.random(size) < 0.5] = 0.0
    return [spread, spread - spread.mean(), holes, np.full(size, -0.0)]


@pytest.mark.parametrize(("task", "prior"), SPACES)
def test_weighted_acceptance_is_bitwise_the_reference(task, prior):
    space = get_space(task, prior)
    graph = execution_graph(space.domain)
    rng = np.random.default_rng(3)
    subsets = [graph.sat, graph.sat[rng.choice(graph.n_nodes, 40)], graph.sat[::-1].copy(), graph.sat[:0]]
    for weights in weight_cases(space.size, rng):
        for sat_masks in subsets:
            fast = space.weighted_acceptance(weights, sat_masks)
            assert same_bits(fast, reference_acceptance(space, weights, sat_masks))


def test_weighted_acceptance_without_blocks_or_one_hypothesis_per_cell():
    dinner = get_domain("dinner")
    space = explicit_space(dinner, {"F(bowl)": 0.5, "G(!fork) & F(bowl)": 0.3, "(!bowl U fork)": 0.2})
    graph = execution_graph(dinner)
    weights = np.array([0.1, 0.7, 0.2])
    assert same_bits(space.weighted_acceptance(weights, graph.sat), reference_acceptance(space, weights, graph.sat))
    shared = HypothesisSpace(dinner, "dup", space.spec, np.array([space.masks[0]] * 2 + [space.masks[1]]),
                             np.log(np.array([0.25, 0.25, 0.5])), space.log_epsilon)  # two share a cell
    w = np.array([0.3, 0.6, 0.1])
    assert same_bits(shared.weighted_acceptance(w, graph.sat), reference_acceptance(shared, w, graph.sat))


@pytest.mark.parametrize(("task", "prior"), SPACES)
def test_satisfied_by_is_the_mask_test(task, prior):
    space = get_space(task, prior)
    graph = execution_graph(space.domain)
    for sat in graph.sat[:: max(1, graph.n_nodes // 50)]:
        assert np.array_equal(space.satisfied_by(int(sat)), (space.masks & ~np.uint64(sat)) == 0)


def plain_summaries(log_weights: np.ndarray) -> tuple[np.ndarray, float]:
    shifted = np.exp(log_weights - log_weights.max())
    probs = shifted / shifted.sum()
    nz = probs[probs > 0]
    return probs, float(-(nz * np.log(nz)).sum())


def test_belief_summaries_are_the_plain_formulas():
    space = get_space("synthetic", "chains-2020-sat")
    graph = execution_graph(space.domain)
    rng = np.random.default_rng(1)
    belief = Belief.prior(space)
    for step in range(8):
        sat = int(graph.sat[rng.integers(graph.n_nodes)])
        acceptable = step < 2 or bool(rng.random() < 0.5)
        before = belief.log_weights
        belief = belief.observe_mask(sat, acceptable)
        assert same_bits(belief.log_weights, before + log_likelihood(space, sat, acceptable))
        probs, entropy = plain_summaries(belief.log_weights)
        assert same_bits(belief.probs, probs) and belief.entropy == entropy
    far = space.log_prior.copy()
    far[rng.random(space.size) < 0.3] -= 800.0  # these underflow to probability 0
    probs, entropy = plain_summaries(far)
    assert (probs == 0).any()
    assert same_bits(Belief(space, far).probs, probs) and Belief(space, far).entropy == entropy
