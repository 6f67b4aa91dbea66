"""Priors: exact enumeration against closed forms and against sampling the generative process."""

import math
from collections import Counter
from itertools import permutations

import numpy as np
import pytest

from tableteach.core.domain import get_domain
from tableteach.core.hypotheses import get_space
from tableteach.core.priors import NAMED_PRIORS, PriorSpec, order_structures


@pytest.mark.parametrize("name", sorted(NAMED_PRIORS))
@pytest.mark.parametrize("task", ["dinner", "synthetic"])
def test_every_prior_is_a_distribution_over_distinct_clause_sets(task, name):
    space = get_space(task, name)
    assert np.exp(space.log_prior).sum() == pytest.approx(1.0, abs=1e-12)
    assert np.unique(space.masks).size == space.size


def test_sizes_of_the_paper_spaces():
    assert len(order_structures(PriorSpec(), 5)) == 501  # sets of linear chains over 5 objects
    assert get_space("dinner", "chains-2020").size == 501 * 32 * 32 == 513_024
    assert get_space("dinner", "chains-2019").size == 501 * 32
    assert len(order_structures(PriorSpec("forest"), 5)) == 6**4  # rooted forests on 5 labelled nodes
    assert len(order_structures(PriorSpec("total-order"), 5)) == 120


def test_chain_probabilities_match_the_closed_form():
    # j blocks: j! of the n! permutations give the structure, with n - j "stay" and j - 1 "cut" decisions
    n, p_new = 5, 0.7
    for pairs, p in order_structures(PriorSpec(p_new_block=p_new), n).items():
        heads = [i for i in range(n) if not any(b == i for _, b in pairs)]  # first element of each block
        j = len(heads)
        expected = math.factorial(j) / math.factorial(n) * (1 - p_new) ** (n - j) * p_new ** (j - 1)
        assert p == pytest.approx(expected, rel=1e-12)


def _sample_chain_structure(rng, n, p_new):
    perm = rng.permutation(n)
    pairs, block = set(), [int(perm[0])]
    for x in perm[1:]:
        if rng.random() < p_new:
            block = []
        pairs |= {(e, int(x)) for e in block}
        block.append(int(x))
    return frozenset(pairs)


def test_enumeration_matches_sampling_the_authors_process():
    rng = np.random.default_rng(7)
    exact = order_structures(PriorSpec(), 4)
    draws = 60_000
    counts = Counter(_sample_chain_structure(rng, 4, 0.7) for _ in range(draws))
    assert set(counts) <= set(exact)
    for key, p in exact.items():
        sd = math.sqrt(p * (1 - p) / draws)
        assert abs(counts[key] / draws - p) < 5 * sd + 1e-9


def test_faithful_2020_prior_is_mostly_self_contradictory():
    space = get_space("dinner", "chains-2020")
    prior = np.exp(space.log_prior)
    # brute force: a formula is satisfiable iff one of the 326 executions satisfies it
    from itertools import permutations as perms
    objects = space.domain.propositions
    executions = [order for k in range(6) for order in perms(objects, k)]
    assert len(executions) == 326
    sat_masks = np.array([space.domain.clause_space.sat_mask(space.domain.trace_of(e)) for e in executions],
                         dtype=np.uint64)
    satisfiable = np.zeros(space.size, dtype=bool)
    for sat in sat_masks:
        satisfiable |= (space.masks & ~sat) == 0
    contradictory_mass = prior[~satisfiable].sum()
    # LEARNER.md says "about 92%"; exact enumeration of its stated process gives 84.4%
    assert contradictory_mass == pytest.approx(0.8443043945, abs=1e-9)
    conditioned = get_space("dinner", "chains-2020-sat")
    assert conditioned.size == int(satisfiable.sum())
    order = np.argsort(space.masks)
    idx = order[np.searchsorted(space.masks[order], conditioned.masks)]
    assert satisfiable[idx].all()
    np.testing.assert_allclose(np.exp(conditioned.log_prior), prior[idx] / prior[satisfiable].sum(), rtol=1e-9)


def test_forest_orders_children_before_ancestors():
    structures = order_structures(PriorSpec("forest", p_root=0.0), 3)
    # with no extra roots, every forest is a single tree: a chain or a star
    for pairs in structures:
        elements = {x for pair in pairs for x in pair}
        assert elements == {0, 1, 2}
    assert sum(structures.values()) == pytest.approx(1.0)
    chains = [s for s in structures if len(s) == 3]
    assert all(any(all((a, b) in s for a, b in [(o[0], o[1]), (o[1], o[2]), (o[0], o[2])])
                   for o in permutations(range(3))) for s in chains)


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="p_new_block"):
        PriorSpec(p_new_block=1.5)
    with pytest.raises(ValueError, match="unknown prior structure"):
        PriorSpec("lattice")
    with pytest.raises(ValueError, match="unknown prior 'uniform'"):
        get_space("dinner", "uniform")
    with pytest.raises(ValueError, match="unknown task 'kitchen'"):
        get_domain("kitchen")
