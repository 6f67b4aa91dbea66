"""Planning with uncertain specifications (PUnS): reward machine and exact planner.

The reward machine of a belief tracks every clause's status (pending, satisfied, violated);
when the episode ends, formula i counts +1 if it accepts, else -1, weighted by a criterion:
- min-regret: the posterior (R = 2 P(acceptable) - 1), the default;
- most-likely: the MAP formula alone;
- most-coverage: every formula in the support equally;
- chance-constrained: the most probable formulas whose mass reaches 1 - risk, renormalised.
The product of the domain with this machine is the execution DAG with stochastic failures as
self-loops; undiscounted, a self-loop does not change an action's value, so backward induction
over the DAG solves the product MDP exactly.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from .belief import Belief
from .executions import ExecutionGraph, execution_graph

CRITERIA = ("min-regret", "most-likely", "most-coverage", "chance-constrained")
SUPPORT_THRESHOLD = 1e-6
TIE_TOLERANCE = 1e-12
_ACCEPTANCE: "weakref.WeakKeyDictionary[Belief, np.ndarray]" = weakref.WeakKeyDictionary()


def node_acceptance(belief: Belief) -> np.ndarray:
    """P(acceptable) of every execution node under a belief (cached per belief object)."""
    cached = _ACCEPTANCE.get(belief)
    if cached is None:
        graph = execution_graph(belief.space.domain)
        cached = belief.space.weighted_acceptance(belief.probs, graph.sat)
        cached.flags.writeable = False
        _ACCEPTANCE[belief] = cached
    return cached


def criterion_weights(
    belief: Belief, criterion: str, *, risk: float = 0.1, support_threshold: float = SUPPORT_THRESHOLD
) -> np.ndarray:
    """Non-negative weights over hypotheses (summing to 1) that define a PUnS criterion."""
    p = belief.probs
    if criterion == "min-regret":
        return p
    if criterion == "most-likely":
        w = np.zeros_like(p)
        w[belief.map_index] = 1.0
        return w
    if criterion == "most-coverage":
        support = p >= support_threshold
        return support / support.sum()
    if criterion == "chance-constrained":
        if not 0.0 <= risk < 1.0:
            raise ValueError(f"risk must be in [0, 1), got {risk}")
        order = np.argsort(-p, kind="stable")
        cumulative = np.cumsum(p[order])
        keep = order[: int(np.searchsorted(cumulative, 1.0 - risk - 1e-12)) + 1]
        w = np.zeros_like(p)
        w[keep] = p[keep]
        return w / w.sum()
    raise ValueError(f"unknown criterion {criterion!r}; expected one of {', '.join(CRITERIA)}")


# ---------------------------------------------------------------- reward machine


@dataclass(frozen=True)
class ClauseStatus:
    """Reward-machine state: which clauses are already satisfied and which are violated."""

    satisfied: int = 0
    violated: int = 0


class RewardMachine:
    """The clause-status reward machine of a weighted set of formulas."""

    def __init__(self, belief: Belief, weights: np.ndarray | None = None) -> None:
        self.belief = belief
        self.space = belief.space.domain.clause_space
        self.weights = belief.probs if weights is None else weights
        self._support = np.flatnonzero(self.weights > 0)
        self._g_bits = sum(1 << i for i, c in enumerate(self.space.clauses) if c.kind == "G")

    def initial(self) -> ClauseStatus:
        """The state before any trace state is read."""
        return ClauseStatus()

    def step(self, u: ClauseStatus, labels: frozenset[str]) -> tuple[ClauseStatus, float, bool]:
        """Read one trace state: (next state, reward, done); reward is paid only when done."""
        sat, viol = u.satisfied, u.violated
        for i, clause in enumerate(self.space.clauses):
            bit = 1 << i
            if (sat | viol) & bit:
                continue  # decided clauses never change (first occurrences only)
            if clause.kind == "G":
                viol |= bit if clause.first in labels else 0
            elif clause.first in labels:  # F(a), or (!b U a) with a now (b at the same time is fine)
                sat |= bit
            elif clause.kind == "U" and clause.second in labels:
                viol |= bit
        nxt = ClauseStatus(sat, viol)
        done = self.decided(nxt)
        return nxt, (self.final_reward(nxt) if done else 0.0), done

    def final_mask(self, u: ClauseStatus) -> int:
        """Clauses that hold if the trace ends now: satisfied ones plus unviolated G clauses."""
        return u.satisfied | (self._g_bits & ~u.violated)

    def final_reward(self, u: ClauseStatus) -> float:
        """Terminal reward: sum_i w_i (+1 if formula i accepts the trace, else -1)."""
        accepted = self.belief.space.satisfied_by(self.final_mask(u))
        return float(2.0 * self.weights[accepted].sum() - self.weights.sum())

    def decided(self, u: ClauseStatus) -> bool:
        """True when no supported formula can change its verdict except by violating a G clause."""
        masks = self.belief.space.masks[self._support]
        pending = np.uint64(self.space.full_mask & ~(u.satisfied | u.violated) & ~self._g_bits)
        violated = (masks & np.uint64(u.violated)) != 0
        return bool(np.all(violated | ((masks & pending) == 0)))


# ---------------------------------------------------------------- exact planner


@dataclass(frozen=True)
class Policy:
    """Solution of the product MDP: per execution node its value and chosen proposition (-1 = stop)."""

    graph: ExecutionGraph
    value: np.ndarray
    action: np.ndarray

    def events_from(self, node: int = 0) -> tuple[str, ...]:
        """The successful moves the policy makes from a node until it stops."""
        props = self.graph.domain.propositions
        events: list[str] = []
        while self.action[node] >= 0:
            a = int(self.action[node])
            events.append(props[a])
            node = int(self.graph.child[node, a])
        return tuple(events)


def node_rewards(belief: Belief, weights: np.ndarray, graph: ExecutionGraph) -> np.ndarray:
    """Terminal reward of stopping at every node: sum_i w_i (+1 accept / -1 reject)."""
    if weights is belief.probs and graph is execution_graph(belief.space.domain):
        accepted = node_acceptance(belief)  # min-regret: shared with the belief's active query
    else:
        accepted = belief.space.weighted_acceptance(weights, graph.sat)
    return 2.0 * accepted - weights.sum()


def solve(
    belief: Belief,
    criterion: str = "min-regret",
    *,
    rng: np.random.Generator | None = None,
    prefer_short: bool = True,
    risk: float = 0.1,
) -> Policy:
    """Exact optimal policy of the product MDP for a belief under a PUnS criterion."""
    graph = execution_graph(belief.space.domain)
    weights = criterion_weights(belief, criterion, risk=risk)
    return backward_induction(graph, node_rewards(belief, weights, graph), rng=rng, prefer_short=prefer_short)


def backward_induction(
    graph: ExecutionGraph,
    stop_value: np.ndarray,
    *,
    rng: np.random.Generator | None = None,
    prefer_short: bool = True,
) -> Policy:
    """Optimal policy given the reward of stopping at each node, solved deepest level first.

    Ties (within 1e-12): with ``prefer_short`` stopping wins, then the child with the shortest
    remaining execution; remaining ties go to ``rng`` (seeded) or else the lowest proposition
    index. Without ``prefer_short`` every optimal action (stop included) is equally likely.
    """
    n, n_props = graph.child.shape
    value = np.full(n, -np.inf)
    steps = np.zeros(n, dtype=np.int64)
    action = np.full(n, -1, dtype=np.int64)
    never = np.iinfo(np.int64).max
    for level in reversed(graph.levels):
        kids = graph.child[level]
        valid = kids >= 0
        safe = np.where(valid, kids, 0)
        # candidate 0 is stop; candidates 1.. are the children
        cand_value = np.concatenate([stop_value[level, None], np.where(valid, value[safe], -np.inf)], axis=1)
        cand_steps = np.concatenate(
            [np.zeros((level.size, 1), dtype=np.int64), np.where(valid, steps[safe] + 1, never)], axis=1
        )
        best = cand_value.max(axis=1)
        tied = cand_value >= best[:, None] - TIE_TOLERANCE
        if prefer_short:
            shortest = np.where(tied, cand_steps, never).min(axis=1)
            tied &= cand_steps == shortest[:, None]
        if rng is not None:
            keys = rng.random(tied.shape)
        else:
            keys = np.broadcast_to(-np.arange(n_props + 1, dtype=np.float64), tied.shape)
        choice = np.argmax(np.where(tied, keys, -np.inf), axis=1)
        value[level] = best
        steps[level] = cand_steps[np.arange(level.size), choice]
        action[level] = choice - 1
    return Policy(graph, value, action)
