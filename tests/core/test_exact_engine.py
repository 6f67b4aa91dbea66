"""The tails DP (core/exact/tails.py) and the constraint batches give the numbers of the subset DP over all objects."""

import numpy as np
import pytest

from tableteach.core.exact.batch import Batch, of_events
from tableteach.core.exact.chains import ChainPrior, _mass
from tableteach.core.exact.constraints import Vocabulary
from tableteach.core.exact.mass import prior_mass
from tableteach.core.exact.tails import antecedents

SETTINGS = [  # (objects, extras, forbiddable objects, p_new_block, require_satisfiable)
    (5, 0, 5, 0.7, True),
    (6, 2, 5, 0.7, False),
    (7, 3, 0, 0.5, True),
    (7, 0, 7, 1.0, False),
]


def _data_constraints(voc: Vocabulary, rng: np.random.Generator, count: int) -> list:
    """Meets of one to three random executions, some without one more clause (not transitive), and single ones."""
    props = voc.orderable + voc.extra
    out = []
    for _ in range(count):
        k = int(rng.integers(1, 4))
        runs = [tuple(rng.permutation(props)[: int(rng.integers(0, len(props) + 1))]) for _ in range(k)]
        batch = of_events(voc, runs).reduce()
        c = batch.row(0)
        if rng.random() < 0.3:
            a, z = rng.choice(voc.n, 2, replace=False)
            c = c.meet(voc.without("U", voc.orderable[a], voc.orderable[z]))
        out.append(c)
    return out


@pytest.mark.parametrize(("n", "m", "forbid", "p_new", "sat"), SETTINGS)
@pytest.mark.parametrize("by_blocks", [False, True])
def test_tails_dp_equals_the_subset_dp(n, m, forbid, p_new, sat, by_blocks):
    rng = np.random.default_rng(n * 10 + m)
    names = tuple(f"o{i}" for i in range(n))
    voc = Vocabulary(names, names[:forbid] + tuple(f"t{j}" for j in range(m)))
    prior = ChainPrior(voc, p_new, 0.5, 0.5, sat)
    cons = _data_constraints(voc, rng, 40)
    batch = Batch.of(cons, n)
    sizes = {bin(int(a)).count("1") for a in antecedents(batch)}
    assert len(sizes) > 2 and max(sizes) < n, sizes  # several antecedent sets, none with every object
    mine = prior_mass(prior, batch, by_blocks)
    reference = _mass(prior, cons, True)
    np.testing.assert_allclose(mine, reference if by_blocks else reference.sum(axis=1), rtol=1e-12, atol=1e-300)


def test_batched_executions_equal_the_vocabulary_one_by_one():
    rng = np.random.default_rng(3)
    names = tuple(f"o{i}" for i in range(6))
    voc = Vocabulary(names, names[:3] + ("t0", "t1"))
    runs = [tuple(rng.permutation(names + ("t0", "t1"))[: int(rng.integers(0, 9))]) for _ in range(50)]
    batch = of_events(voc, runs)
    assert [batch.row(i) for i in range(len(runs))] == [voc.of_events(r) for r in runs]


@pytest.mark.parametrize(("n", "m", "forbid", "p_new", "sat"), SETTINGS[:3])
def test_tails_dp_with_token_weights_equals_the_subset_dp(n, m, forbid, p_new, sat):
    """Random complex weights per similarity token (the expected similarity's DP) give the same masses."""
    from tableteach.core.exact.chains import TokenWeights

    rng = np.random.default_rng(n + m)
    names = tuple(f"o{i}" for i in range(n))
    voc = Vocabulary(names, names[:forbid] + tuple(f"t{j}" for j in range(m)))
    prior = ChainPrior(voc, p_new, 0.5, 0.5, sat)
    cons = _data_constraints(voc, rng, 24)

    def weights(*shape):
        return rng.random((len(cons), *shape)) + 1j * rng.random((len(cons), *shape))

    tokens = TokenWeights(weights(n), weights(n), weights(n, n), weights(m))
    mine = prior_mass(prior, Batch.of(cons, n), tokens=tokens)
    reference = _mass(prior, cons, False, tokens)[:, 0]
    np.testing.assert_allclose(mine, reference, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kept_executions_reach_every_score(seed):
    """Every execution scores the same as one the search's moves keep, and the moves keep fewer."""
    from itertools import permutations

    from tableteach.core.domain import Domain
    from tableteach.core.exact.learner import posterior_after
    from tableteach.core.exact.moves import Moves

    rng = np.random.default_rng(seed)
    objects, threats = ("a", "b", "c", "d", "e"), ("t0", "t1")
    domain = Domain("small", objects + threats, objects, threats, False, 1.0, "visit")
    props = objects + threats
    picks = [tuple(rng.permutation(props[:4])[: int(rng.integers(2, 5))]) for _ in range(3)]
    data = [(domain.trace_of(picks[0]), True), (domain.trace_of(picks[0][::-1]), True),
            (domain.trace_of(picks[1] + ("t0",)), bool(rng.random() < 0.5)), (domain.trace_of(picks[2]), False)]
    post = posterior_after(domain, "chains-2020", data)
    moves = Moves.of(post, props)
    kept, stack = [], [((), 0)]
    while stack:
        events, used = stack.pop()
        kept.append(tuple(props[i] for i in events))
        stack += [(events + (z,), used | 1 << z) for z in moves.children(events, used)]
    everything = [e for k in range(len(props) + 1) for e in permutations(props, k)]
    voc = post.prior.vocabulary
    mine = post.p_within([voc.of_events(e) for e in kept])
    every = post.p_within([voc.of_events(e) for e in everything])
    assert len(kept) < len(everything) / 4
    gaps = np.abs(every[:, None] - mine[None, :]).min(axis=1)
    assert gaps.max() < 1e-12


def test_memoised_masses_are_each_rows_own_masses():
    """A constraint met again, in another batch beside other rows, gets the masses computed for it alone."""
    from tableteach.core.exact import mass

    n, m, forbid, p_new, sat = SETTINGS[1]
    rng = np.random.default_rng(17)
    names = tuple(f"o{i}" for i in range(n))
    voc = Vocabulary(names, names[:forbid] + tuple(f"t{j}" for j in range(m)))
    prior = ChainPrior(voc, p_new, 0.5, 0.5, sat)
    cons = _data_constraints(voc, rng, 30)
    mass.clear_memo()
    first = prior_mass(prior, Batch.of(cons[:20], n))
    mixed = cons[10:] + cons[:5]
    again = prior_mass(prior, Batch.of(mixed, n))
    np.testing.assert_array_equal(again[:10], first[10:20])
    np.testing.assert_allclose(again, _mass(prior, mixed, False)[:, 0], rtol=1e-12, atol=1e-300)


def test_the_scored_query_keeps_the_first_of_its_ties_whatever_the_rounding(monkeypatch):
    """Equal scores that differ in their last bits (another order of the same sums) pick the same execution."""
    from tableteach.core.domain import Domain
    from tableteach.core.exact import search
    from tableteach.core.exact.learner import posterior_after
    from tableteach.core.exact.moves import Moves

    objects = ("a", "b", "c", "d", "e")
    domain = Domain("five", objects, objects, objects, True, 1.0, "place")
    data = [(domain.trace_of(("a", "b", "c")), True), (domain.trace_of(("a", "d", "b", "c")), True)]
    post = posterior_after(domain, "chains-2020-sat", data)
    voc = post.prior.vocabulary
    every = search._kept_executions(Moves.of(post, objects), search.EXHAUSTIVE_ACTIVE)
    scores = np.abs(2 * post.p_within([voc.of_events([objects[i] for i in e]) for e in every]) - 1)
    tied = [e for e, s in zip(every, scores, strict=True) if s <= scores.min() + 1e-12]
    assert len(tied) > 1
    plain = search.best_execution(post, objects, "active", ties="first")
    assert plain.proven and plain.events == tuple(objects[i] for i in tied[0])
    exact = post.p_within
    rng = np.random.default_rng(0)
    monkeypatch.setattr(post, "p_within", lambda batch: exact(batch) * (1 + rng.uniform(-4e-16, 4e-16, len(batch))))
    for _ in range(5):
        assert search.best_execution(post, objects, "active", ties="first").events == plain.events
