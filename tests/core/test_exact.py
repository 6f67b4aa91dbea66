"""The exact factorised learner against the enumerating learner (n <= 5) and a brute force written here (n = 6)."""

import math
from itertools import permutations, product

import numpy as np
import pytest

from tableteach.core.belief import Belief
from tableteach.core.domain import Domain, get_domain
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import build_space, get_space
from tableteach.core.puns import node_acceptance
from tableteach.core.exact.chains import ChainPrior, prior_mass_by_count
from tableteach.core.exact.constraints import Vocabulary
from tableteach.core.exact.learner import chain_prior, posterior_after

CASES = [
    ("dinner", "chains-2020-sat"),
    ("dinner", "chains-2020"),
    ("dinner", "chains-2019"),
    ("dinner", "total-order"),
    ("synthetic", "chains-2020"),
]


def _random_data(domain, rng, count):
    graph = execution_graph(domain)
    nodes = rng.choice(graph.n_nodes, count)
    return [(domain.trace_of(graph.events[i]), bool(rng.random() < 0.6)) for i in nodes]


def _enumerated(space, data):
    """The enumerating learner's belief after the labelled traces."""
    belief = Belief.prior(space)
    for trace, ok in data:
        belief = belief.observe(trace, ok)
    return belief


@pytest.mark.parametrize(("task", "prior"), CASES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_p_acceptable_agrees_with_enumeration(task, prior, seed):
    rng = np.random.default_rng(seed)
    domain = get_domain(task)
    data = _random_data(domain, rng, int(rng.integers(0, 6)))
    belief = _enumerated(get_space(task, prior), data)
    post = posterior_after(domain, prior, data)
    graph = execution_graph(domain)
    nodes = rng.choice(graph.n_nodes, 40, replace=False)
    mine = post.p_within([post.prior.vocabulary.of_events(graph.events[i]) for i in nodes])
    np.testing.assert_allclose(mine, node_acceptance(belief)[nodes], atol=1e-9, rtol=0)


def test_epsilon_terms_are_used_when_they_matter():
    """Two contradicting demonstrations: every formula but the empty one violates one; eps terms decide."""
    domain = get_domain("dinner")
    data = [(domain.trace_of(("bowl", "fork")), True), (domain.trace_of(("fork", "bowl")), True),
            (domain.trace_of(()), True), (domain.trace_of(("knife",)), False)]
    post = posterior_after(domain, "chains-2020-sat", data)
    belief = _enumerated(get_space("dinner", "chains-2020-sat"), data)
    graph = execution_graph(domain)
    mine = post.p_within([post.prior.vocabulary.of_events(e) for e in graph.events])
    np.testing.assert_allclose(mine, node_acceptance(belief), atol=1e-9, rtol=0)


def test_marginals_agree_with_enumeration():
    rng = np.random.default_rng(5)
    domain = get_domain("dinner")
    data = _random_data(domain, rng, 3)
    space = get_space("dinner", "chains-2020-sat")
    belief = _enumerated(space, data)
    clauses = domain.clause_space
    post = posterior_after(domain, "chains-2020-sat", data)
    for (kind, first, second), p in post.marginals().items():
        bit = clauses.bit(next(c for c in clauses.clauses if (c.kind, c.first, c.second) == (kind, first, second)))
        expected = belief.probs[(space.masks & np.uint64(bit)) != 0].sum()
        assert p == pytest.approx(expected, abs=1e-9), (kind, first, second)


@pytest.mark.parametrize("prior", ["chains-2019", "chains-2020", "chains-2020-sat"])
def test_prior_mass_by_clause_count_matches_enumeration(prior):
    space = get_space("dinner", prior)
    chains, _ = chain_prior(get_domain("dinner"), prior)
    z = prior_mass_by_count(chains, [chains.vocabulary.everything()])[0]
    expected = np.bincount(space.nconj, weights=np.exp(space.log_prior), minlength=z.size)
    np.testing.assert_allclose(z / z.sum(), expected[: z.size], atol=1e-12)


# ------------------------------------------------------------ six objects, by brute force

SIX = tuple(f"o{i}" for i in range(6))


def _brute_force_hypotheses(n, p_new, p_eventually):
    """Every chains-2019 hypothesis over n objects as (F set, ordered pairs) with its prior (perms and cuts)."""
    structures: dict[frozenset, float] = {}
    for perm in permutations(range(n)):
        for cuts in product((False, True), repeat=n - 1):
            p = math.prod(p_new if c else 1 - p_new for c in cuts) / math.factorial(n)
            pairs, block = set(), [perm[0]]
            for element, cut in zip(perm[1:], cuts, strict=True):
                if cut:
                    block = []
                pairs.update((e, element) for e in block)
                block.append(element)
            key = frozenset(pairs)
            structures[key] = structures.get(key, 0.0) + p
    out = []
    for pairs, p in structures.items():
        for f in range(1 << n):
            k = bin(f).count("1")
            out.append((f, pairs, p * p_eventually**k * (1 - p_eventually) ** (n - k)))
    return out


def _satisfies(f, pairs, events):
    first = {SIX.index(e): t for t, e in enumerate(events)}
    if any(f >> i & 1 and i not in first for i in range(6)):
        return False
    return all(a in first and (b not in first or first[a] < first[b]) for a, b in pairs)


def test_six_objects_agree_with_brute_force():
    rng = np.random.default_rng(11)
    domain = Domain("six", SIX, SIX, (), True, 1.0, "place")
    hyps = _brute_force_hypotheses(6, 0.7, 0.5)
    n_clauses = np.array([bin(f).count("1") + len(pairs) for f, pairs, _ in hyps], dtype=float)
    log_w = np.log([p for _, _, p in hyps])
    log_eps = -4.0 * (6 + 15) * math.log(2)
    data = []
    for _ in range(4):
        events = tuple(rng.permutation(SIX)[: int(rng.integers(0, 7))])
        data.append((events, bool(rng.random() < 0.6)))
    for events, ok in data:
        sat = np.array([_satisfies(f, pairs, events) for f, pairs, _ in hyps])
        if ok:
            log_w += np.where(sat, n_clauses * math.log(2), log_eps)
        else:
            with np.errstate(divide="ignore"):
                log_w += np.where(sat, log_eps, np.where(n_clauses > 0, -np.log1p(-np.exp2(-n_clauses)), log_eps))
    probs = np.exp(log_w - log_w.max())
    probs /= probs.sum()
    post = posterior_after(domain, "chains-2019", [(domain.trace_of(e), ok) for e, ok in data])
    queries = [tuple(rng.permutation(SIX)[: int(rng.integers(0, 7))]) for _ in range(12)]
    mine = post.p_within([post.prior.vocabulary.of_events(q) for q in queries])
    expected = [probs[[_satisfies(f, pairs, q) for f, pairs, _ in hyps]].sum() for q in queries]
    np.testing.assert_allclose(mine, expected, atol=1e-9, rtol=0)


def test_constraints_refuse_unknown_sizes():
    domain = Domain("one", ("a",), ("a",), ("a",), True, 1.0, "place")
    with pytest.raises(ValueError, match="2 to 10"):
        chain_prior(domain, "chains-2020")
    with pytest.raises(ValueError, match="forest"):
        chain_prior(get_domain("dinner"), "forest")


def test_total_mass_is_one_at_ten_objects():
    names = tuple(f"o{i}" for i in range(10))
    prior = ChainPrior(Vocabulary(names, names))
    assert prior_mass_by_count(prior, [prior.vocabulary.everything()])[0].sum() == pytest.approx(1.0, abs=1e-12)



# ------------------------------------------------------------ search against exhaustive scoring

FOUR = ("a", "b", "c", "d")


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("scored_all", [True, False])
def test_search_finds_the_exhaustive_optimum(seed, scored_all, monkeypatch):
    """Both ways to the active query (every kept execution scored, or the branch and bound) and the plan."""
    from tableteach.core.exact import search
    from tableteach.core.exact.search import best_execution

    if not scored_all:
        monkeypatch.setattr(search, "EXHAUSTIVE_ACTIVE", 0)

    rng = np.random.default_rng(seed)
    domain = Domain("four", FOUR, FOUR, FOUR, True, 1.0, "place")
    space = build_space(domain, "chains-2020-sat")
    data = _random_data(domain, rng, 3)
    belief = _enumerated(space, data)
    acceptance = node_acceptance(belief)
    post = posterior_after(domain, "chains-2020-sat", data)
    plan = best_execution(post, FOUR, "min-regret")
    query = best_execution(post, FOUR, "active", max_expansions=10_000)
    assert plan.proven and query.proven
    assert plan.p_acceptable == pytest.approx(acceptance.max(), abs=1e-9)
    assert abs(2 * query.p_acceptable - 1) == pytest.approx(np.abs(2 * acceptance - 1).min(), abs=1e-9)


@pytest.mark.parametrize(("task", "prior"), CASES)
def test_entropy_agrees_with_enumeration(task, prior):
    rng = np.random.default_rng(21)
    domain = get_domain(task)
    data = _random_data(domain, rng, 3)
    belief = _enumerated(get_space(task, prior), data)
    post = posterior_after(domain, prior, data)
    assert post.entropy() == pytest.approx(belief.entropy, abs=1e-9)
    blocks = post.block_count_distribution()
    assert blocks.sum() == pytest.approx(1.0, abs=1e-9)


# ------------------------------------------------------------ the MAP formula


def _map_log_probability_in(belief, domain, text):
    """The enumerating learner's log probability of a formula given as text (the MAP's ties all score the same)."""
    mask = domain.clause_space.mask_of_formula(text) if text != "true" else 0
    index = np.flatnonzero(belief.space.masks == np.uint64(mask))
    assert index.size == 1, text
    return math.log(belief.probs[index[0]])


@pytest.mark.parametrize(("task", "prior"), CASES)
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_map_agrees_with_enumeration(task, prior, seed):
    """The exact MAP's probability is the enumerated maximum; among ties any maximiser is accepted."""
    from tableteach.core.exact.mapping import log_prior, map_formula

    rng = np.random.default_rng(seed)
    domain = get_domain(task)
    data = _random_data(domain, rng, int(rng.integers(0, 7)))
    belief = _enumerated(get_space(task, prior), data)
    post = posterior_after(domain, prior, data)
    result = map_formula(post)
    best = math.log(belief.probs[belief.map_index])
    assert result.log_probability == pytest.approx(best, abs=1e-9)
    assert _map_log_probability_in(belief, domain, result.text) == pytest.approx(best, abs=1e-9)
    z0 = prior_mass_by_count(post.prior, [post.prior.vocabulary.everything()])[0].sum()
    enumerated_prior = get_space(task, prior).log_prior  # normalised over the support
    mask = domain.clause_space.mask_of_formula(result.text) if result.text != "true" else 0
    index = np.flatnonzero(get_space(task, prior).masks == np.uint64(mask))[0]
    assert log_prior(post.prior, result.formula) - math.log(z0) == pytest.approx(enumerated_prior[index], abs=1e-9)


def test_map_at_six_objects_agrees_with_brute_force():
    from tableteach.core.exact.mapping import map_formula

    rng = np.random.default_rng(12)
    domain = Domain("six", SIX, SIX, (), True, 1.0, "place")
    hyps = _brute_force_hypotheses(6, 0.7, 0.5)
    n_clauses = np.array([bin(f).count("1") + len(pairs) for f, pairs, _ in hyps], dtype=float)
    log_w = np.log([p for _, _, p in hyps])
    log_eps = -4.0 * (6 + 15) * math.log(2)
    data = []
    for _ in range(5):
        events = tuple(rng.permutation(SIX)[: int(rng.integers(0, 7))])
        ok = bool(rng.random() < 0.6)
        sat = np.array([_satisfies(f, pairs, events) for f, pairs, _ in hyps])
        if ok:
            log_w += np.where(sat, n_clauses * math.log(2), log_eps)
        else:
            with np.errstate(divide="ignore"):
                log_w += np.where(sat, log_eps, np.where(n_clauses > 0, -np.log1p(-np.exp2(-n_clauses)), log_eps))
        data.append((events, ok))
    log_z = np.logaddexp.reduce(log_w)
    post = posterior_after(domain, "chains-2019", [(domain.trace_of(e), o) for e, o in data])
    result = map_formula(post)
    assert result.log_probability == pytest.approx(float(log_w.max() - log_z), abs=1e-9)
    f = result.formula
    pairs = frozenset((a, z) for z, p in enumerate(f.pred) for a in range(6) if p >> a & 1)
    mine = next(i for i, (hf, hp, _) in enumerate(hyps) if hf == f.f and hp == pairs)
    assert log_w[mine] == pytest.approx(log_w.max(), abs=1e-9)


# ------------------------------------------------------------ exact samples


def _formula_mask(domain, prior, formula):
    space = domain.clause_space
    return sum(space.bit(c) for c in formula.clauses(prior))


def _chi_square_p(counts, expected):
    """Pearson's chi-square p-value (Wilson-Hilferty), cells with expected count under 5 pooled into one."""
    small = expected < 5
    obs = np.r_[counts[~small], counts[small].sum()]
    exp = np.r_[expected[~small], expected[small].sum()]
    keep = exp > 0
    stat = float((((obs - exp) ** 2)[keep] / exp[keep]).sum())
    k = int(keep.sum()) - 1
    z = ((stat / k) ** (1 / 3) - (1 - 2 / (9 * k))) / math.sqrt(2 / (9 * k))
    return 0.5 * math.erfc(z / math.sqrt(2))


SAMPLE_DATA = [
    [(("a", "b"), True), (("b", "a", "c"), False), (("a", "c", "b"), True)],  # 16 formulas carry the mass
    [(("b", "a"), False)],  # 240 cells with an expected count of 5 or more
]


@pytest.mark.parametrize("labelled", SAMPLE_DATA)
def test_samples_follow_the_exact_posterior(labelled):
    """4,000 draws at four objects against the enumerated posterior (fixed seed; the prior, as a wrong
    answer, must be rejected by the same test)."""
    from tableteach.core.exact.sampling import sample_formulas

    domain = Domain("four", FOUR, FOUR, FOUR, True, 1.0, "place")
    space = build_space(domain, "chains-2020")
    data = [(domain.trace_of(events), ok) for events, ok in labelled]
    belief = _enumerated(space, data)
    post = posterior_after(domain, "chains-2020", data)
    draws = sample_formulas(post, 4000, np.random.default_rng(7))
    index = {int(m): i for i, m in enumerate(space.masks)}
    counts = np.bincount([index[_formula_mask(domain, post.prior, h)] for h in draws], minlength=space.size)
    assert _chi_square_p(counts.astype(float), belief.probs * len(draws)) > 1e-4
    prior = np.exp(space.log_prior - np.logaddexp.reduce(space.log_prior))
    assert _chi_square_p(counts.astype(float), prior * len(draws)) < 1e-4


# ------------------------------------------------------------ expected similarity


@pytest.mark.parametrize(("task", "prior"), CASES)
@pytest.mark.parametrize("seed", [0, 1])
def test_expected_similarity_agrees_with_enumeration(task, prior, seed):
    """Against Belief.similarity for a random truth of the support, the empty formula and the MAP."""
    from tableteach.core.exact.similarity import expected_similarity

    rng = np.random.default_rng(seed)
    domain = get_domain(task)
    data = _random_data(domain, rng, int(rng.integers(0, 5)))
    space = get_space(task, prior)
    belief = _enumerated(space, data)
    post = posterior_after(domain, prior, data)
    clauses = domain.clause_space
    for truth in (int(space.masks[rng.integers(space.size)]), 0, belief.map_mask):
        mine = expected_similarity(post, clauses.clauses_of(truth))
        assert mine == pytest.approx(belief.similarity(truth), abs=1e-9), clauses.text_of(truth)


def test_expected_similarity_refuses_unknown_truths_and_metrics():
    from tableteach.core.clauses import Clause
    from tableteach.core.exact.similarity import expected_similarity

    post = posterior_after(get_domain("dinner"), "chains-2020", [])
    with pytest.raises(ValueError, match="spoon"):
        expected_similarity(post, [Clause("F", "spoon")])
    with pytest.raises(ValueError, match="strict"):
        expected_similarity(post, [], metric="strict")
