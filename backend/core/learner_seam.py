"""The one seam through which the server asks its learner anything: the enumerating learner up to five objects,
the exact factorised learner (core.exact) past five.

Both answer the same questions about the belief after some labelled executions: P(acceptable) of an execution,
the entropy, the expected similarity to a ground truth, the MAP formula with its probability, every clause's
marginal, the active query and the min-regret plan. They differ in one view: the enumerating learner lists the
k most probable formulas, the exact learner lists none (up to 6e13 at ten objects) and gives the MAP formula
alone with its exact probability (``top`` returns that one), plus the clause marginals.

What the exact learner cannot do yet is refused by name, never approximated (``exact_problems``): the
noise-aware likelihood (flip rate above 0), priors without a factorised form (forest) and PUnS criteria other
than min-regret. Up to five objects every answer is the enumerating learner's, computed exactly as before this
seam existed (same functions, same random draws), so a dinner study's exports and states do not change.
"""

from __future__ import annotations

import math
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from functools import lru_cache
from typing import Any, Literal, Sequence

import numpy as np

from .belief import Belief
from .clauses import Clause
from .domain import Domain, get_domain
from .enumerated_beliefs import noisy_belief_after
from .exact.learner import SUPPORTED_STRUCTURES, posterior_after
from .exact.mapping import map_formula
from .exact.posterior import ExactPosterior
from .exact.search import best_execution
from .exact.similarity import expected_similarity
from .ltl_semantics import Trace
from .metrics import similarity as mask_similarity
from .priors import get_prior
from .queries import Execution, plan_execution, query, rollout

ENUMERATED_UP_TO = 5  # objects: past this the enumerated space (16.6 million formulas at six) is too large
PATHS = ("auto", "enumerating", "exact")
Path = Literal["enumerating", "exact"]
EXACT_CRITERIA = ("min-regret",)
EXACT_QUERIES = ("active", "random")
Verdicts = tuple[tuple[Trace, bool, bool], ...]  # (trace, acceptable, is_verdict), as core.session has it


def path_of(task: str, path: str = "auto") -> Path:
    """Which learner answers for a task: 'enumerating' up to five orderable objects, 'exact' past five ('auto'),
    or the one named (tests force the exact path on small tasks to check one learner against the other)."""
    if path not in PATHS:
        raise ValueError(f"unknown learner path {path!r}; expected one of {', '.join(PATHS)}")
    if path != "auto":
        return path  # type: ignore[return-value]
    return "exact" if len(get_domain(task).orderable) > ENUMERATED_UP_TO else "enumerating"


def exact_problems(prior: str, flip_rate: float = 0.0, criterion: str = "min-regret") -> list[tuple[str, str]]:
    """(setting, why) for each learner setting the exact learner past five objects does not offer yet."""
    out = []
    spec = get_prior(prior)
    if spec.structure not in SUPPORTED_STRUCTURES:
        out.append(("prior", f"the prior {prior!r} has no exact factorised form past {ENUMERATED_UP_TO} objects; "
                             "expected a chains or total-order prior (e.g. chains-2020-sat)"))
    if flip_rate != 0.0:
        out.append(("flip_rate", f"the noise-aware learner (flip rate {flip_rate:g}) is not available past "
                                 f"{ENUMERATED_UP_TO} objects yet; expected 0 (the authors' learner)"))
    if criterion not in EXACT_CRITERIA:
        out.append(("criterion", f"the planning criterion {criterion!r} is not available past {ENUMERATED_UP_TO} "
                                 f"objects; expected {' or '.join(EXACT_CRITERIA)}"))
    return out


def check_exact(prior: str, flip_rate: float = 0.0, criterion: str = "min-regret") -> None:
    """ValueError naming every setting the exact learner does not offer (``exact_problems``)."""
    problems = exact_problems(prior, flip_rate, criterion)
    if problems:
        raise ValueError("; ".join(why for _, why in problems))


class LearnerBelief(ABC):
    """The belief after some labelled executions, as the server asks about it (either learner)."""

    path: Path
    domain: Domain

    @property
    @abstractmethod
    def entropy(self) -> float:
        """Shannon entropy (nats) over canonical clause sets."""

    @abstractmethod
    def p_acceptable(self, trace: Trace) -> float:
        """Posterior probability that an execution with this trace is acceptable."""

    @abstractmethod
    def similarity(self, truth_mask: int) -> float:
        """Expected similarity E_P[L(phi, truth)] (the authors' metric) to a clause set of the task's ClauseSpace."""

    @property
    @abstractmethod
    def map_mask(self) -> int:
        """The most probable formula as a clause set of the task's ClauseSpace."""

    @property
    @abstractmethod
    def map_probability(self) -> float:
        """The MAP formula's posterior probability."""

    @abstractmethod
    def top(self, k: int) -> list[tuple[int, float]]:
        """The most probable formulas as (mask, probability): the k most probable (enumerating learner), or the
        MAP alone (exact learner, which does not list formulas)."""

    @abstractmethod
    def marginals(self) -> dict[Clause, float]:
        """P(clause in the formula) for every template clause of the task."""

    def map_similarity(self, truth_mask: int) -> float:
        """Similarity of the MAP formula to the truth."""
        return mask_similarity(self.domain.clause_space, self.map_mask, truth_mask)

    def top_marginals(self, k: int) -> list[tuple[Clause, float]]:
        """The k clauses most probably in the formula, most probable first (ties in the clause space's order)."""
        order = {c: i for i, c in enumerate(self.domain.clause_space.clauses)}
        ranked = sorted(self.marginals().items(), key=lambda kv: (-kv[1], order[kv[0]]))
        return ranked[: max(k, 0)]


class EnumeratedBelief(LearnerBelief):
    """The enumerating learner's belief (core.belief): every formula listed."""

    path: Path = "enumerating"

    def __init__(self, belief: Belief) -> None:
        self.belief = belief
        self.domain = belief.space.domain

    @property
    def entropy(self) -> float:
        return self.belief.entropy

    def p_acceptable(self, trace: Trace) -> float:
        return self.belief.p_acceptable(trace)

    def similarity(self, truth_mask: int) -> float:
        return self.belief.similarity(truth_mask)

    @property
    def map_mask(self) -> int:
        return self.belief.map_mask

    @property
    def map_probability(self) -> float:
        return float(self.belief.probs[self.belief.map_index])

    def top(self, k: int) -> list[tuple[int, float]]:
        return self.belief.top(k)

    def map_similarity(self, truth_mask: int) -> float:
        return self.belief.map_similarity(truth_mask)

    def marginals(self) -> dict[Clause, float]:
        space = self.belief.space
        probs = self.belief.probs
        out = {}
        for i, clause in enumerate(space.domain.clause_space.clauses):
            has = ((space.masks >> np.uint64(i)) & np.uint64(1)).astype(bool)
            out[clause] = float(probs[has].sum())
        return out


class ExactBelief(LearnerBelief):
    """The exact factorised learner's belief (core.exact): nothing listed, everything computed exactly. Each answer
    is computed once (past eight objects the MAP takes a minute): two threads asking at once wait for one answer."""

    path: Path = "exact"

    def __init__(self, domain: Domain, posterior: ExactPosterior) -> None:
        self.domain = domain
        self.posterior = posterior
        self._lock = threading.Lock()
        self._known: dict[object, Any] = {}

    def _once(self, key: object, compute: Callable[[], Any]) -> Any:
        with self._lock:
            if key not in self._known:
                self._known[key] = compute()
            return self._known[key]

    @property
    def entropy(self) -> float:
        return float(self._once("entropy", self.posterior.entropy))

    def p_acceptable(self, trace: Trace) -> float:
        return self.posterior.p_acceptable(self.posterior.prior.vocabulary.of_trace([frozenset(s) for s in trace]))

    def similarity(self, truth_mask: int) -> float:
        truth = self.domain.clause_space.clauses_of(truth_mask)
        return float(self._once(("similarity", truth_mask), lambda: expected_similarity(self.posterior, truth)))

    def _map(self) -> tuple[int, float]:
        def compute() -> tuple[int, float]:
            best = map_formula(self.posterior)
            space = self.domain.clause_space
            mask = 0
            for clause in best.formula.clauses(self.posterior.prior):
                mask |= space.bit(clause)
            return mask, math.exp(best.log_probability)

        return self._once("map", compute)

    @property
    def map_mask(self) -> int:
        return self._map()[0]

    @property
    def map_probability(self) -> float:
        return self._map()[1]

    def top(self, k: int) -> list[tuple[int, float]]:
        return [self._map()] if k > 0 else []

    def marginals(self) -> dict[Clause, float]:
        def compute() -> dict[Clause, float]:
            found = {Clause(kind, first, second): p for (kind, first, second), p in self.posterior.marginals().items()}
            # A prior without G clauses (chains-2019) never forbids: those clauses have marginal 0.
            return {c: found.get(c, 0.0) for c in self.domain.clause_space.clauses}

        return dict(self._once("marginals", compute))


# ---------------------------------------------------------------- beliefs


def _check_flip(flip_rate: float) -> None:
    if flip_rate != 0.0:
        raise ValueError(f"the noise-aware learner (flip rate {flip_rate:g}) is not available past "
                         f"{ENUMERATED_UP_TO} objects yet; expected flip rate 0 (the authors' learner)")


def belief_after(task: str, prior: str, flip_rate: float, data: Verdicts, path: str = "auto") -> LearnerBelief:
    """The learner's belief after these (trace, acceptable, is_verdict) items, in order; ValueError names a
    setting the exact learner does not offer (``exact_problems``)."""
    if path_of(task, path) == "enumerating":
        return EnumeratedBelief(noisy_belief_after(task, prior, flip_rate, data))
    return exact_belief_after(task, prior, flip_rate, data)


@lru_cache(maxsize=256)  # a few kB each: the posterior's weights over satisfaction patterns, and what was asked
def exact_belief_after(task: str, prior: str, flip_rate: float, data: Verdicts) -> ExactBelief:
    """The exact learner's belief after these items (any number of objects from 2 to 10)."""
    _check_flip(flip_rate)
    domain = get_domain(task)
    posterior = posterior_after(domain, prior, [([sorted(s) for s in trace], acceptable)
                                                for trace, acceptable, _ in data])
    return ExactBelief(domain, posterior)


# ---------------------------------------------------------------- robot turns


def robot_query(task: str, prior: str, flip_rate: float, data: Verdicts, strategy: str, rng: np.random.Generator,
                path: str = "auto") -> tuple[Execution, float]:
    """A query by strategy ('active': the most uncertain execution; 'random'), with its P(acceptable).

    Exact learner: the active query is core.exact.search's, seeded from the turn's generator; where it scores
    every kept execution, its ties are drawn uniformly as the enumerating learner's are, where it searches
    (too many executions kept) it keeps the first found."""
    belief = belief_after(task, prior, flip_rate, data, path)
    if isinstance(belief, EnumeratedBelief):
        return query(belief.belief, strategy, rng)
    assert isinstance(belief, ExactBelief)
    domain = belief.domain
    if strategy == "active":
        found = best_execution(belief.posterior, domain.propositions, "active", seed=int(rng.integers(2**31)))
        return rollout(domain, found.events, rng), found.p_acceptable
    if strategy == "random":
        execution = _random_execution(domain, rng)
        return execution, belief.p_acceptable(execution.trace)
    raise ValueError(f"query strategy {strategy!r} is not available past {ENUMERATED_UP_TO} objects; expected one "
                     f"of {', '.join(EXACT_QUERIES)}")


def robot_plan(task: str, prior: str, flip_rate: float, data: Verdicts, criterion: str, rng: np.random.Generator,
               path: str = "auto") -> tuple[Execution, float]:
    """The robot's best execution under a PUnS criterion (past five objects: min-regret, by the exact learner's
    branch and bound, proven optimal), with its P(acceptable)."""
    belief = belief_after(task, prior, flip_rate, data, path)
    if isinstance(belief, EnumeratedBelief):
        return plan_execution(belief.belief, criterion, rng)
    assert isinstance(belief, ExactBelief)
    if criterion not in EXACT_CRITERIA:
        raise ValueError(f"criterion {criterion!r} is not available past {ENUMERATED_UP_TO} objects; expected "
                         f"{' or '.join(EXACT_CRITERIA)}")
    events, p = _exact_plan(task, prior, data)
    return rollout(belief.domain, events, rng), p


@lru_cache(maxsize=64)  # a task's test executions share one belief (tests teach nothing): one search for all
def _exact_plan(task: str, prior: str, data: Verdicts) -> tuple[tuple[str, ...], float]:
    """The exact learner's min-regret execution and its P(acceptable) (deterministic: no random draw)."""
    belief = exact_belief_after(task, prior, 0.0, data)
    found = best_execution(belief.posterior, belief.domain.propositions, "min-regret")
    return found.events, found.p_acceptable


def _random_execution(domain: Domain, rng: np.random.Generator) -> Execution:
    """A uniformly random action each step (stop included) until the execution stops (core.queries.random_query's
    walk, without a belief)."""
    history: tuple[str, ...] = ()
    trace = [domain.labels(history)]
    while True:
        actions = domain.actions(history)
        action = actions[int(rng.integers(len(actions)))]
        if action is None:
            return Execution(history, tuple(trace))
        history = domain.step(history, action, rng)
        trace.append(domain.labels(history))


def verdict_probability(belief: LearnerBelief, trace: Trace, acceptable: bool) -> float:
    """The probability the belief gave to a verdict: P(acceptable) for an accept, 1 - P(acceptable) for a reject."""
    p = belief.p_acceptable(trace)
    return p if acceptable else 1.0 - p


def clause_texts(items: Sequence[tuple[Clause, float]]) -> list[dict[str, object]]:
    """Clause marginals as JSON-ready rows: the clause's text and its probability."""
    return [{"clause": c.text(), "p": p} for c, p in items]
