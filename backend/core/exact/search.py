"""Min-regret plans and most-uncertain queries by best-first branch and bound over execution prefixes.

An execution is the order in which propositions first became true; every clause depends only on
that, so a prefix bounds every extension of it: an extension is accepted by at most the formulas
the prefix has not yet violated (``upper``), and by at least those it has already satisfied for
good (``lower``: its F items and its orders whose antecedent occurred, no G clause). Both bounds
and the scores are exact posterior probabilities. The min-regret plan maximises P(acceptable);
the active query minimises |2 P(acceptable) - 1|. Only one execution of each set that provably
scores the same is visited (``moves.py``). When the moves keep at most ``EXHAUSTIVE_ACTIVE``
executions, the active query scores all of them in one batch (proven); its ties (scores within
``TOLERANCE`` of the least, whatever their last bits) are drawn uniformly among every tied execution,
kept or not, from the seed (``ties.py``), or with ``ties="first"`` the first, shortest and in
proposition order. Past that it searches. With ``max_expansions`` large enough the search is
exhaustive where the bounds do not prune, so its result is the proven optimum
(``SearchResult.proven``); otherwise it is the best execution found. Prefixes are expanded
``batch_size`` at a time (lowest bound first, then ``_priority``), their children scored in one
batched DP, then their bounds in another (a query needs only the bound on the side of 1/2 that its
own score is on). The active query starts from the best of ``dives`` seeded random walks (every child on
the way scored), which the many ties favour, so the bounds prune from the start. The search's ties
keep the first found.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .batch import Batch, of_events
from .constraints import Constraint, Vocabulary
from .moves import Moves, lower
from .posterior import ExactPosterior
from .ties import draw_tied

TOLERANCE = 1e-12
OBJECTIVES = ("min-regret", "active")
TIES = ("uniform", "first")  # the active query's, where it scored every kept execution
# The active query's bounds rarely prune (most prefixes can still end either way), so it gets a budget.
DEFAULT_EXPANSIONS = {"min-regret": 2_000, "active": 64}
# Up to this many executions kept by the moves, the active query scores them all (one batch) and is proven.
EXHAUSTIVE_ACTIVE = 5_000


@dataclass(frozen=True)
class SearchResult:
    """The best execution found, its P(acceptable), how many prefixes were expanded, and if it is proven."""

    events: tuple[str, ...]
    p_acceptable: float
    expanded: int
    proven: bool


def upper_constraint(voc: Vocabulary, events: Sequence[str]) -> Constraint:
    """Clauses that the prefix has not violated: what some extension may still satisfy."""
    first = {p: t for t, p in reversed(list(enumerate(events)))}
    n = voc.n
    g_ok = sum(1 << i for i, p in enumerate(voc.orderable) if p not in first) & voc.forbiddable_orderable
    into = []
    for pz in voc.orderable:
        allowed = 0
        for a, pa in enumerate(voc.orderable):
            if pa != pz and (pz not in first or (pa in first and first[pa] <= first[pz])):
                allowed |= 1 << a
        into.append(allowed)
    g_extra = sum(1 << j for j, p in enumerate(voc.extra) if p not in first)
    return Constraint(g_ok, (1 << n) - 1, tuple(into), g_extra)


def lower_constraint(voc: Vocabulary, events: Sequence[str]) -> Constraint:
    """Clauses every extension of the prefix satisfies: occurred F items, orders whose antecedent occurred first."""
    sat = voc.of_events(events)
    return Constraint(0, sat.f_ok, sat.into, 0)


@dataclass(frozen=True)
class _Node:
    """A prefix: proposition indices, the used ones as a mask, its satisfied and not-yet-violated clauses."""

    events: tuple[int, ...]
    used: int
    exact: Batch
    upper: Batch


def _children(moves: Moves, nodes: Sequence[_Node]) -> list[_Node]:
    """Every allowed one-proposition extension of the nodes, in order."""
    parents, props = [], []
    for k, node in enumerate(nodes):
        for z in moves.children(node.events, node.used):
            parents.append(k)
            props.append(z)
    if not props:
        return []
    index = np.array(parents)
    exact = Batch.concat([node.exact for node in nodes]).take(index)
    upper = Batch.concat([node.upper for node in nodes]).take(index)
    child, bound = moves.extend(exact, upper, np.array(props))
    return [_Node(nodes[k].events + (z,), nodes[k].used | 1 << z, child.take(np.array([c])), bound.take(np.array([c])))
            for c, (k, z) in enumerate(zip(parents, props, strict=True))]


def best_execution(
    posterior: ExactPosterior,
    propositions: Sequence[str],
    objective: str = "min-regret",
    max_expansions: int | None = None,
    batch_size: int = 8,
    dives: int = 8,
    seed: int = 0,
    ties: str = "uniform",
) -> SearchResult:
    """The execution (propositions in order of first occurrence) that is best for the objective."""
    if objective not in OBJECTIVES:
        raise ValueError(f"unknown search objective {objective!r}; expected one of {', '.join(OBJECTIVES)}")
    if ties not in TIES:
        raise ValueError(f"unknown tie rule {ties!r}; expected one of {', '.join(TIES)}")
    if max_expansions is None:
        max_expansions = DEFAULT_EXPANSIONS[objective]
    voc = posterior.prior.vocabulary
    moves = Moves.of(posterior, propositions)
    n = voc.n
    if objective == "active" and max_expansions > 0:
        every = _kept_executions(moves, EXHAUSTIVE_ACTIVE)
        if every is not None:
            probs = posterior.p_within(of_events(voc, [tuple(moves.names[i] for i in e) for e in every]))
            scores = np.abs(2.0 * probs - 1.0)
            tied = np.flatnonzero(scores <= scores.min() + TOLERANCE)  # equal scores may differ in their last bits
            k, events = int(tied[0]), every[int(tied[0])]
            if ties == "uniform":
                drawn, events = draw_tied(moves, [every[int(t)] for t in tied], np.random.default_rng(seed))
                k = int(tied[drawn])
            return SearchResult(tuple(moves.names[i] for i in events), float(probs[k]), len(every), True)
    root = _Node((), 0, Batch.of([voc.of_events(())], n), Batch.of([voc.everything()], n))
    root_p, lo, hi = posterior.p_within(Batch.concat([root.exact, lower(root.exact), root.upper]))
    best: tuple[tuple[int, ...], float, float] = ((), float(root_p), _score(objective, float(root_p)))
    if objective == "active" and dives > 0:  # ties are many: random dives find a strong incumbent fast
        best = min(best, _random_dives(posterior, moves, root, dives, np.random.default_rng(seed)),
                   key=lambda item: item[2])
    frontier: list[tuple[float, float, int, _Node]] = [(_bound(objective, float(lo), float(hi)), best[2], 0, root)]
    expanded = 0
    counter = 0
    perfect = -1.0 if objective == "min-regret" else 0.0  # nothing scores better than this
    while frontier and expanded < max_expansions and best[2] > perfect + TOLERANCE:
        batch: list[_Node] = []
        while frontier and len(batch) < batch_size and expanded + len(batch) < max_expansions:
            bound, _, _, node = heapq.heappop(frontier)
            if bound < best[2] - TOLERANCE:
                batch.append(node)
        expanded += len(batch)
        children = _children(moves, batch)
        if not children:
            continue
        exact = Batch.concat([c.exact for c in children])
        probs = posterior.p_within(exact)
        for child, p in zip(children, probs, strict=True):
            score = _score(objective, float(p))
            if score < best[2] - TOLERANCE:
                best = (child.events, float(p), score)
        if best[2] <= perfect + TOLERANCE:  # nothing can beat it: the children's bounds are not needed
            break
        open_ = np.array([k for k, c in enumerate(children) if len(c.events) < len(moves.names)], dtype=np.int64)
        if open_.size == 0:
            continue
        upper = Batch.concat([children[k].upper for k in open_.tolist()])
        bounds = _bounds(posterior, objective, exact.take(open_), upper, probs[open_])
        for k, child_bound in zip(open_.tolist(), bounds.tolist(), strict=True):
            if child_bound < best[2] - TOLERANCE:
                counter += 1
                heapq.heappush(frontier, (child_bound, _priority(objective, float(probs[k]), len(children[k].events)),
                                          counter, children[k]))
    proven = best[2] <= perfect + TOLERANCE or not any(b < best[2] - TOLERANCE for b, _, _, _ in frontier)
    return SearchResult(tuple(moves.names[i] for i in best[0]), best[1], expanded, proven)


def _kept_executions(moves: Moves, cap: int) -> list[tuple[int, ...]] | None:
    """Every execution the moves keep, shortest first and in proposition order; None if there are more than cap."""
    level: list[tuple[tuple[int, ...], int]] = [((), 0)]
    out: list[tuple[int, ...]] = []
    while level:
        out += [events for events, _ in level]
        if len(out) > cap:
            return None
        level = [(events + (z,), used | 1 << z) for events, used in level for z in moves.children(events, used)]
    return out


def _score(objective: str, p: float) -> float:
    """Lower is better: -P(acceptable) for plans, |2P - 1| for queries."""
    return -p if objective == "min-regret" else abs(2.0 * p - 1.0)


def _bound(objective: str, lo: float, hi: float) -> float:
    """A lower bound on the score of any extension whose P(acceptable) lies in [lo, hi]."""
    if objective == "min-regret":
        return -hi
    if lo <= 0.5 <= hi:
        return 0.0
    return min(abs(2.0 * lo - 1.0), abs(2.0 * hi - 1.0))


def _bounds(posterior: ExactPosterior, objective: str, exact: Batch, upper: Batch, probs: np.ndarray) -> np.ndarray:
    """``_bound`` for many prefixes with their own P(acceptable) probs. Since lo <= P <= hi, a query needs only
    hi when P < 1/2 and only lo when P > 1/2 (the other side cannot change the bound), so only that one is scored."""
    if objective == "min-regret":
        return -posterior.p_within(upper)
    below, above = np.flatnonzero(probs < 0.5), np.flatnonzero(probs > 0.5)
    values = posterior.p_within(Batch.concat([upper.take(below), lower(exact.take(above))]))
    hi, lo = values[:below.size], values[below.size:]
    out = np.zeros(probs.size)
    out[below] = np.where(hi >= 0.5, 0.0, np.abs(2.0 * hi - 1.0))
    out[above] = np.where(lo <= 0.5, 0.0, np.abs(2.0 * lo - 1.0))
    return out


def _priority(objective: str, p: float, depth: int) -> float:
    """Among prefixes with equal bounds, which to expand first: plans the best own score; queries dive
    (deepest first, then the best own score), since their bounds rarely prune shallow prefixes."""
    if objective == "min-regret":
        return -p
    return -depth + abs(2.0 * p - 1.0)


def _random_dives(
    posterior: ExactPosterior, moves: Moves, root: _Node, dives: int, rng: np.random.Generator
) -> tuple[tuple[int, ...], float, float]:
    """The most uncertain execution seen on ``dives`` uniformly random walks from the empty execution,
    every child along the way scored (one batched DP per depth)."""
    best: tuple[tuple[int, ...], float, float] = ((), 0.0, 2.0)
    paths = [root] * dives
    while paths:
        children = _children(moves, paths)
        if not children:
            break
        probs = posterior.p_within(Batch.concat([c.exact for c in children]))
        for child, p in zip(children, probs, strict=True):
            if abs(2.0 * p - 1.0) < best[2] - TOLERANCE:
                best = (child.events, float(p), abs(2.0 * float(p) - 1.0))
        walks = []
        for path in paths:
            mine = [c for c in children if c.events[:-1] == path.events]
            if mine and len(path.events) + 1 < len(moves.names):
                walks.append(mine[int(rng.integers(len(mine)))])
        paths = walks
    return best
