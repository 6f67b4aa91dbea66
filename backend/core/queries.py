"""Robot executions: min-regret plans, active (uncertainty-sampling) queries and random queries.

Active query: among every reachable end of an execution, the one whose probability of being
acceptable is closest to 1/2 (min-regret reward closest to 0). Ties are the rule (tens to
hundreds of equally uncertain executions): "uniform" (default, as the authors' softmax over equal
values) draws one of them with the seeded rng; "shortest" keeps only the shortest tied ones
first; "stepwise" walks from the start choosing uniformly at each step among the actions (stop
included) that can still reach a tied execution, as a greedy policy over equal Q-values would
(long executions with many orderings get less weight than under "uniform"); "uniform-executions"
draws a tied execution summary with probability proportional to the number of move sequences it
summarises (synthetic: the orders in which its threats were visited among the waypoints; dinner:
always 1, the same as "uniform"). The robot then plans a path to it. Random query: a uniformly random action
(stop included) each step until the execution ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .belief import Belief
from .domain import STOP, Domain
from .executions import ExecutionGraph, execution_graph
from .puns import TIE_TOLERANCE, backward_induction, node_acceptance, solve

QUERY_STRATEGIES = ("active", "random")
QUERY_TIES = ("uniform", "shortest", "stepwise", "uniform-executions")
DEFAULT_QUERY_TIES = "uniform"


@dataclass(frozen=True)
class Execution:
    """A robot execution: the propositions it made true in order and the resulting trace."""

    events: tuple[str, ...]
    trace: tuple[frozenset[str], ...]

    def to_json(self) -> dict:
        """JSON-ready form: events and the trace as sorted lists."""
        return {"events": list(self.events), "trace": [sorted(s) for s in self.trace]}


def rollout(domain: Domain, events: tuple[str, ...], rng: np.random.Generator) -> Execution:
    """Carry out a sequence of intended moves, retrying failed moves until each succeeds."""
    history: tuple[str, ...] = ()
    trace = [domain.labels(history)]
    for event in events:
        while True:
            nxt = domain.step(history, event, rng)
            trace.append(domain.labels(nxt))
            if nxt != history:
                history = nxt
                break
    return Execution(tuple(events), tuple(trace))


def plan_execution(
    belief: Belief, criterion: str = "min-regret", rng: np.random.Generator | None = None, risk: float = 0.1
) -> tuple[Execution, float]:
    """The robot's best execution under a PUnS criterion, with its P(acceptable) under the belief."""
    rng = rng or np.random.default_rng(0)
    policy = solve(belief, criterion, rng=rng, risk=risk)
    events = policy.events_from(0)
    execution = rollout(belief.space.domain, events, rng)
    return execution, belief.p_acceptable(execution.trace)


def active_query(
    belief: Belief, rng: np.random.Generator | None = None, ties: str = DEFAULT_QUERY_TIES
) -> tuple[Execution, float]:
    """The execution the robot is least sure about, with its P(acceptable); ties as named in QUERY_TIES."""
    if ties not in QUERY_TIES:
        raise ValueError(f"unknown query tie-breaking {ties!r}; expected one of {', '.join(QUERY_TIES)}")
    rng = rng or np.random.default_rng(0)
    graph = execution_graph(belief.space.domain)
    p_accept = node_acceptance(belief)
    score = np.abs(2.0 * p_accept - 1.0)
    if ties == "stepwise":
        policy = backward_induction(graph, -score, rng=rng, prefer_short=False)
        node = 0
        while policy.action[node] >= 0:
            node = int(graph.child[node, policy.action[node]])
        execution = rollout(belief.space.domain, graph.events[node], rng)
        return execution, float(p_accept[node])
    tied = score <= score.min() + TIE_TOLERANCE
    if ties == "shortest":
        tied &= graph.depth == graph.depth[tied].min()
    candidates = np.flatnonzero(tied)
    if ties == "uniform-executions" and candidates.size > 1:
        weights = _sequences_per_node(graph)[candidates]
        node = int(rng.choice(candidates, p=weights / weights.sum()))
    else:
        node = int(candidates[rng.integers(candidates.size)]) if candidates.size > 1 else int(candidates[0])
    execution = rollout(belief.space.domain, graph.events[node], rng)
    return execution, float(p_accept[node])


@lru_cache(maxsize=None)
def _sequences_per_node(graph: ExecutionGraph) -> np.ndarray:
    """How many orders of first visits each execution summary stands for: d! / m! for d items, m orderable."""
    ordered = np.array([len(key[0]) for key in graph.keys])
    return np.array([math.perm(int(d), int(d - m)) for d, m in zip(graph.depth, ordered, strict=True)], dtype=float)


def random_query(belief: Belief, rng: np.random.Generator) -> tuple[Execution, float]:
    """A uniformly random execution (stop included at every step), with its P(acceptable)."""
    domain = belief.space.domain
    history: tuple[str, ...] = ()
    trace = [domain.labels(history)]
    while True:
        actions = domain.actions(history)
        action = actions[int(rng.integers(len(actions)))]
        if action is STOP:
            break
        history = domain.step(history, action, rng)
        trace.append(domain.labels(history))
    return Execution(tuple(history), tuple(trace)), belief.p_acceptable(trace)


def query(
    belief: Belief, strategy: str, rng: np.random.Generator, ties: str = DEFAULT_QUERY_TIES
) -> tuple[Execution, float]:
    """A query by strategy name ('active' or 'random')."""
    if strategy == "active":
        return active_query(belief, rng, ties)
    if strategy == "random":
        return random_query(belief, rng)
    raise ValueError(f"unknown query strategy {strategy!r}; expected one of {', '.join(QUERY_STRATEGIES)}")
