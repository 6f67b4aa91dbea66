"""The exact learner's uniform draw among tied active queries (core/exact/ties.py) against brute force, 5-6 objects."""

from itertools import permutations

import numpy as np
import pytest

from tableteach.core.domain import Domain
from tableteach.core.exact import search, ties
from tableteach.core.exact.learner import posterior_after
from tableteach.core.exact.moves import Moves

FIVE, SIX = tuple("abcde"), tuple("abcdef")
CASES = [  # (objects, threats, prior, data): each regime of ties.py, and kept executions sharing a class
    (FIVE, (), "chains-2020-sat", [(("a", "b"), True), (("a",), True)]),
    (FIVE, (), "chains-2020-sat", [(("a", "b"), True), (("b", "a"), True), ((), True), (("c",), False)]),
    (FIVE, (), "chains-2020-sat", [(("b", "a"), False)]),  # no acceptable execution: nothing commutes
    (("a", "b", "c", "d"), ("t0", "t1", "t2"), "chains-2020", [(("a", "b"), True), (("a",), True)]),
    (SIX, ("t0",), "chains-2020", [(("d", "b", "e", "c"), False), (("t0", "a", "e", "f"), True), (("a", "c"), True),
                                   (("b", "e", "a", "d"), True)]),
]


def _setting(objects, threats, prior, data):
    """The posterior, its moves, and every execution as a summary (objects' order, threats visited) with its score."""
    props = objects + threats
    domain = Domain("ties", props, objects, props if threats else objects, not threats, 1.0,
                    "visit" if threats else "place")
    post = posterior_after(domain, prior, [(domain.trace_of(e), ok) for e, ok in data])
    moves = Moves.of(post, props)
    summaries = {}
    for k in range(len(props) + 1):
        for events in permutations(range(len(props)), k):
            summaries.setdefault(_summary(objects, events), events)
    executions = list(summaries.values())
    voc = post.prior.vocabulary
    scores = np.abs(2 * post.p_within([voc.of_events([props[i] for i in e]) for e in executions]) - 1)
    return post, moves, executions, scores


def _summary(objects, events):
    return tuple(z for z in events if z < len(objects)), frozenset(z for z in events if z >= len(objects))


def _tied_kept(post, moves):
    every = search._kept_executions(moves, 10**9)
    voc = post.prior.vocabulary
    scores = np.abs(2 * post.p_within([voc.of_events([moves.names[i] for i in e]) for e in every]) - 1)
    return [every[k] for k in np.flatnonzero(scores <= scores.min() + search.TOLERANCE)], scores.min()


@pytest.mark.parametrize("case", range(len(CASES)))
def test_the_tied_kept_executions_stand_for_every_tied_execution_once(case):
    """Every tied execution (brute force) is in the class of a tied kept one, and each class holds as many
    tied executions as class_size says."""
    objects, threats, prior, data = CASES[case]
    post, moves, executions, scores = _setting(*CASES[case])
    tied_kept, best = _tied_kept(post, moves)
    assert scores.min() == pytest.approx(best, abs=1e-12)
    tied = [e for e, s in zip(executions, scores, strict=True) if s <= best + 1e-9]
    found: dict = {}
    for events in tied:
        found[ties.class_key(moves, events)] = found.get(ties.class_key(moves, events), 0) + 1
    stands = {ties.class_key(moves, e): e for e in reversed(tied_kept)}
    assert set(found) == set(stands)
    assert {key: ties.class_size(moves, e) for key, e in stands.items()} == found
    assert len(tied) > len(stands)  # classes hold more than the kept executions


def test_tied_queries_are_drawn_uniformly():
    """A tie rule's draws over 492 tied executions (18 kept ones in 8 classes) are uniform (chi-square), and
    each is a tied execution."""
    objects, threats, prior, data = CASES[4]
    post, moves, executions, scores = _setting(*CASES[4])
    tied_kept, best = _tied_kept(post, moves)
    tied = {_summary(objects, e) for e, s in zip(executions, scores, strict=True) if s <= best + 1e-9}
    assert len(tied) == 492 and len(tied_kept) == 18
    counts = dict.fromkeys(tied, 0)
    rng = np.random.default_rng(3)
    draws = 10 * len(tied)
    for _ in range(draws):
        _, events = ties.draw_tied(moves, tied_kept, rng)
        counts[_summary(objects, events)] += 1
    observed = np.array(list(counts.values()))
    chi2 = float(((observed - 10) ** 2 / 10).sum())
    dof = len(tied) - 1
    assert chi2 < dof + 4 * np.sqrt(2 * dof)


def test_the_active_query_draws_a_tied_execution_from_its_seed():
    objects, threats, prior, data = CASES[1]
    post, moves, executions, scores = _setting(*CASES[1])
    tied = {_summary(objects, e) for e, s in zip(executions, scores, strict=True) if s <= scores.min() + 1e-9}
    drawn = set()
    for seed in range(40):
        found = search.best_execution(post, objects, "active", seed=seed)
        assert found.proven and abs(2 * found.p_acceptable - 1) == pytest.approx(scores.min(), abs=1e-12)
        assert found == search.best_execution(post, objects, "active", seed=seed)
        drawn.add(_summary(objects, tuple(objects.index(p) for p in found.events)))
    assert drawn <= tied and len(drawn) > len(tied) / 2
    first = search.best_execution(post, objects, "active", ties="first")
    assert all(search.best_execution(post, objects, "active", seed=s, ties="first") == first for s in range(3))
    with pytest.raises(ValueError, match="tie rule"):
        search.best_execution(post, objects, "active", ties="softmax")
