"""Robot executions: min-regret plans, active queries (uncertainty sampling or expected information gain)
and random queries.

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

Information-gain query (ours, not the authors'): among every reachable end of an execution, one that
maximises the expected drop in the belief's entropy, exactly over the enumerated hypotheses, with
the verdict predicted by the belief (flipped with the learner's flip rate, if any); ties uniform.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .belief import Belief, likelihood_terms
from .domain import STOP, Domain
from .executions import ExecutionGraph, execution_graph
from .puns import TIE_TOLERANCE, backward_induction, node_acceptance, solve

QUERY_STRATEGIES = ("active", "information-gain", "random")
ACTIVE_STRATEGIES = ("uncertainty", "information-gain")  # how the Active protocol picks a query
DEFAULT_ACTIVE_STRATEGY = "uncertainty"
# Gains are sums over ~10^5 hypotheses: executions with equal gains differ by rounding (~1e-13 nats).
GAIN_TIE_TOLERANCE = 1e-9
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


def expected_information_gain(belief: Belief, sat_masks: np.ndarray, flip_rate: float = 0.0) -> np.ndarray:
    """Expected entropy drop (nats) of the belief from the verdict on each execution (by satisfied-clause mask)."""
    space = belief.space
    lw = belief.log_weights - belief.log_weights.max()
    log_q = lw - np.log(np.exp(lw).sum())
    p_sat = space.weighted_acceptance(np.exp(log_q), sat_masks)
    p_accept = (1.0 - flip_rate) * p_sat + flip_rate * (1.0 - p_sat)
    expected = np.zeros(len(sat_masks))
    for acceptable, p_outcome in ((True, p_accept), (False, 1.0 - p_accept)):
        ll_sat, ll_viol = likelihood_terms(space, acceptable, flip_rate)
        top = max(ll_sat.max(), ll_viol.max())  # rescaling the posterior leaves its entropy unchanged
        log_a, log_b = log_q + ll_sat - top, log_q + ll_viol - top
        a, b = np.exp(log_a), np.exp(log_b)
        # Unnormalised posterior u (a where satisfied, b where violated): H = log Z - sum(u log u) / Z.
        z = space.weighted_acceptance(a - b, sat_masks) + b.sum()
        t = space.weighted_acceptance(a * log_a - b * log_b, sat_masks) + (b * log_b).sum()
        # The violated part of z is a difference of sums, exact only to ~1e-16 of the total: an outcome less
        # likely than 1e-12 is left out (it moves the gain by less than 1e-10 nats).
        likely = p_outcome > 1e-12
        safe_z = np.where(likely, z, 1.0)
        expected += np.where(likely, p_outcome * (np.log(safe_z) - t / safe_z), 0.0)
    return belief.entropy - expected


def information_gain_query(
    belief: Belief, rng: np.random.Generator | None = None, flip_rate: float = 0.0
) -> tuple[Execution, float]:
    """The execution whose verdict is expected to tell the most (max expected information gain), with its
    P(acceptable); ties drawn uniformly with the rng."""
    rng = rng or np.random.default_rng(0)
    graph = execution_graph(belief.space.domain)
    gain = expected_information_gain(belief, graph.sat, flip_rate)
    candidates = np.flatnonzero(gain >= gain.max() - GAIN_TIE_TOLERANCE)
    node = int(candidates[rng.integers(candidates.size)]) if candidates.size > 1 else int(candidates[0])
    execution = rollout(belief.space.domain, graph.events[node], rng)
    return execution, float(node_acceptance(belief)[node])


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
    """A query by strategy name ('active' is uncertainty sampling, 'information-gain', or 'random')."""
    if strategy == "active":
        return active_query(belief, rng, ties)
    if strategy == "information-gain":
        return information_gain_query(belief, rng)
    if strategy == "random":
        return random_query(belief, rng)
    raise ValueError(f"unknown query strategy {strategy!r}; expected one of {', '.join(QUERY_STRATEGIES)}")
