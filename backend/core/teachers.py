"""Simulated teachers and ground truths for experiments and scripted sessions.

A teacher knows a ground-truth formula (a clause-set mask). Its demonstration modes:

- "required-only" (default; the authors' demonstrator): only the required items, the F items
  and the antecedent a of every order (!b U a), in an order drawn uniformly from the orders of
  that set that satisfy every order clause, then stop. Never a forbidden or optional item.
- "optimal": an optimal policy for reward +1 on every satisfying execution, random tie-breaking
  (it performs optional items and threats the truth allows);
- "uniform": uniformly random among all satisfying executions;
- "fixed": an optimal policy with fixed tie-breaking that repeats the same demonstration
  (stop as soon as possible, lowest index first).

It assesses an execution by checking the formula, flipping its verdict with probability
``noise`` (the paper assumed a perfect teacher; people are not).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import permutations

import numpy as np

from .clauses import ClauseSpace
from .domain import Domain
from .executions import execution_graph
from .hypotheses import HypothesisSpace
from .puns import backward_induction
from .queries import Execution, rollout

DEMO_MODES = ("required-only", "optimal", "uniform", "fixed")
DEFAULT_DEMO_MODE = "required-only"


def satisfying_nodes(domain: Domain, truth_mask: int) -> np.ndarray:
    """Boolean array over execution nodes: which executions satisfy the ground truth."""
    graph = execution_graph(domain)
    return (np.uint64(truth_mask) & ~graph.sat) == 0


def is_satisfiable(domain: Domain, truth_mask: int) -> bool:
    """Whether some execution of the domain satisfies the formula."""
    return bool(satisfying_nodes(domain, truth_mask).any())


def sample_ground_truth(space: HypothesisSpace, rng: np.random.Generator, max_tries: int = 10_000) -> int:
    """Draw a formula from the prior, keeping only satisfiable ones."""
    probs = np.exp(space.log_prior - space.log_prior.max())
    probs /= probs.sum()
    for _ in range(max_tries):
        mask = int(space.masks[rng.choice(space.size, p=probs)])
        if is_satisfiable(space.domain, mask):
            return mask
    raise RuntimeError(f"no satisfiable formula in {max_tries} draws from prior {space.prior_name!r}")


def authors_ground_truth(domain: Domain, rng: np.random.Generator) -> int:
    """The authors' experiment sampler: chains in index order, new block w.p. 0.5, F w.p. 0.5, no G."""
    space = domain.clause_space
    mask = 0
    block: list[str] = []
    for i, p in enumerate(domain.orderable):
        if i > 0 and rng.random() < 0.5:
            block = []
        for earlier in block:
            mask |= space.before_bit(earlier, p)
        block.append(p)
        if rng.random() < 0.5:
            mask |= space.f_bit(p)
    return mask


def required_items(space: ClauseSpace, truth_mask: int) -> tuple[str, ...]:
    """Propositions the truth requires: its F items and the antecedent a of every (!b U a)."""
    need = {c.first for c in space.clauses_of(truth_mask) if c.kind in ("F", "U")}
    return tuple(p for p in space.orderable if p in need)


@lru_cache(maxsize=4096)
def valid_orders(space: ClauseSpace, truth_mask: int) -> tuple[tuple[str, ...], ...]:
    """Every order of the required items that satisfies every order clause of the truth."""
    items = required_items(space, truth_mask)
    pairs = [(c.first, c.second) for c in space.clauses_of(truth_mask) if c.kind == "U" and c.second in items]
    out = []
    for order in permutations(items):
        at = {p: i for i, p in enumerate(order)}
        if all(at[a] < at[b] for a, b in pairs):
            out.append(order)
    return tuple(out)


@dataclass(frozen=True)
class SimulatedTeacher:
    """A teacher who knows the ground truth and demonstrates and assesses accordingly."""

    domain: Domain
    truth_mask: int
    noise: float = 0.0
    demo_mode: str = DEFAULT_DEMO_MODE

    def __post_init__(self) -> None:
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be a probability in [0, 1], got {self.noise}")
        if self.demo_mode not in DEMO_MODES:
            raise ValueError(f"unknown demonstration mode {self.demo_mode!r}; expected one of {', '.join(DEMO_MODES)}")
        if not is_satisfiable(self.domain, self.truth_mask):
            text = self.domain.clause_space.text_of(self.truth_mask)
            raise ValueError(f"ground truth {text!r} cannot be satisfied, so it cannot be demonstrated")

    def demonstrate(self, rng: np.random.Generator) -> Execution:
        """One demonstration: an execution that satisfies the ground truth."""
        if self.demo_mode == "required-only":
            orders = valid_orders(self.domain.clause_space, self.truth_mask)
            return rollout(self.domain, orders[int(rng.integers(len(orders)))], rng)
        graph = execution_graph(self.domain)
        good = satisfying_nodes(self.domain, self.truth_mask)
        if self.demo_mode == "uniform":
            node = int(rng.choice(np.flatnonzero(good)))
            events = graph.events[node]
        else:
            tie_rng = rng if self.demo_mode == "optimal" else None
            policy = backward_induction(graph, np.where(good, 1.0, -1.0), rng=tie_rng, prefer_short=False)
            events = policy.events_from(0)
        return rollout(self.domain, events, rng)

    def assess(self, trace: tuple[frozenset[str], ...] | list[frozenset[str]], rng: np.random.Generator) -> bool:
        """The teacher's verdict on an execution: acceptable or not (flipped w.p. noise)."""
        sat = self.domain.clause_space.sat_mask(trace)
        verdict = (self.truth_mask & ~sat) == 0
        if self.noise > 0 and rng.random() < self.noise:
            verdict = not verdict
        return bool(verdict)
