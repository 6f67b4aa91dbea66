"""What the learner's command line prints for tasks past enumeration, in the same JSON shapes."""

from __future__ import annotations

import math
import time
from functools import lru_cache
from typing import Any, Sequence

import numpy as np

from ..belief import LabelledExecution
from ..clauses import describe_clauses
from ..domain import Domain
from ..hypotheses import HypothesisSpace, build_space
from .learner import posterior_after
from .mapping import map_formula
from .posterior import ExactPosterior
from .search import best_execution

ENUMERATED_UP_TO = 5  # objects; past this the factorised learner answers
EXACT_CRITERIA = ("min-regret",)


@lru_cache(maxsize=8)
def enumerated_space(domain: Domain, prior: str) -> HypothesisSpace:
    """The enumerated hypothesis space of a small task with its own objects."""
    return build_space(domain, prior)


def _posterior(domain: Domain, prior: str, executions: Sequence[LabelledExecution]) -> ExactPosterior:
    data: list[tuple[Sequence[Sequence[str]], bool]] = [([sorted(state) for state in e.trace], e.acceptable)
                                                        for e in executions]
    return posterior_after(domain, prior, data)


def _clause_text(kind: str, first: str, second: str | None) -> str:
    if kind == "G":
        return f"G(!{first})"
    if kind == "F":
        return f"F({first})"
    return f"(!{second} U {first})"


def infer(domain: Domain, prior: str, executions: Sequence[LabelledExecution], top: int) -> dict[str, Any]:
    """The posterior's entropy, clause marginals and MAP formula; the support lists the MAP only (the
    whole support has up to 6e13 formulas, and the exact learner finds the top one, not the top k)."""
    started = time.perf_counter()
    post = _posterior(domain, prior, executions)
    marginals = sorted(post.marginals().items(), key=lambda kv: -kv[1])
    best = map_formula(post)
    clauses = best.formula.clauses(post.prior)
    return {
        "support": [{"formula": best.text, "clauses": [c.text() for c in clauses],
                     "p": math.exp(best.log_probability), "description": describe_clauses(clauses, domain.verb)}],
        "entropy": post.entropy(),
        "map": best.text,
        "n_hypotheses": None,
        "marginals": [{"clause": _clause_text(*key), "p": p} for key, p in marginals[: max(top, 0)]],
        "learner": "exact-factorised",
        "seconds": time.perf_counter() - started,
    }


def query(
    domain: Domain, prior: str, executions: Sequence[LabelledExecution], strategy: str, seed: int
) -> dict[str, Any]:
    """The most uncertain execution (active) or a uniformly random one (random), with P(acceptable)."""
    post = _posterior(domain, prior, executions)
    started = time.perf_counter()
    if strategy == "active":
        result = best_execution(post, domain.propositions, "active")
        events, p = result.events, result.p_acceptable
    else:
        events = random_events(domain, np.random.default_rng(seed))
        p = post.p_acceptable(post.prior.vocabulary.of_events(events))
    return {"execution": list(events), "p_acceptable": p, "seconds": time.perf_counter() - started}


def plan(domain: Domain, prior: str, executions: Sequence[LabelledExecution], criterion: str) -> dict[str, Any]:
    """The min-regret execution, found by branch and bound."""
    if criterion not in EXACT_CRITERIA:
        raise ValueError(
            f"criterion {criterion!r} is not available past {ENUMERATED_UP_TO} objects; expected one of "
            f"{', '.join(EXACT_CRITERIA)}"
        )
    post = _posterior(domain, prior, executions)
    started = time.perf_counter()
    result = best_execution(post, domain.propositions, "min-regret")
    return {"execution": list(result.events), "p_acceptable": result.p_acceptable,
            "seconds": time.perf_counter() - started}


def random_events(domain: Domain, rng: np.random.Generator) -> tuple[str, ...]:
    """A uniformly random action each step (stop included) until the execution stops."""
    history: tuple[str, ...] = ()
    while True:
        actions = domain.actions(history)
        action = actions[int(rng.integers(len(actions)))]
        if action is None:
            return history
        history = domain.step(history, action, rng)
