"""One simulated run with the exact factorised learner, for synthetic domains past enumeration.

The same protocols, streams and rows as ``simulate.simulate_run``, with the exact learner's answers:
entropy, expected similarity, MAP formula (``core/exact``), active queries and min-regret test plans
by branch and bound, random queries as uniformly random actions. Differences from the enumerated
sweep: ground truths are exact prior draws kept when satisfiable (the same distribution, another
use of the stream); among equally uncertain executions the active query keeps the search's first
(seeded by the protocol's stream), not a uniform draw; only the authors' similarity, the default
uncertainty strategy, required-only demonstrations and a learner without flip rate are offered.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from ..core.clauses import Clause
from ..core.domain import Domain, synthetic_domain
from ..core.exact.commands import random_events
from ..core.exact.learner import prior_posterior
from ..core.exact.mapping import Formula, map_formula
from ..core.exact.posterior import Datum, ExactPosterior
from ..core.exact.sampling import sample_formulas
from ..core.exact.search import best_execution
from ..core.exact.similarity import expected_similarity, truth_tokens
from ..core.queries import rollout
from ..core.session import PROTOCOLS
from .settings import ExperimentSettings
from .run_rows import protocol_rows


@dataclass(frozen=True)
class _Step:
    kind: str
    entropy: float
    similarity: float
    map_similarity: float
    map_formula: str
    seconds: float
    test_success: int | None = None


@lru_cache(maxsize=4)
def _start(n_waypoints: int, n_threats: int, prior: str) -> tuple[Domain, ExactPosterior]:
    domain = synthetic_domain(n_waypoints, n_threats)
    return domain, prior_posterior(domain, prior)


def satisfiable(h: Formula) -> bool:
    """Whether some execution satisfies the formula: nothing both forbidden and required or ordered first."""
    antecedents = sum(1 << z for chain in h.chains for z in chain[:-1])
    return (h.g & (h.f | antecedents)) == 0


def _truth(post: ExactPosterior, rng: np.random.Generator) -> Formula:
    for _ in range(10_000):
        h = sample_formulas(post, 1, rng)[0]
        if satisfiable(h):
            return h
    raise RuntimeError("no satisfiable ground truth in 10,000 prior draws")


def _demonstration(domain: Domain, post: ExactPosterior, truth: Formula, rng: np.random.Generator) -> Any:
    """The required items (F items, antecedents of orders) in a uniformly drawn order that keeps every order."""
    names = post.prior.vocabulary.orderable
    pred = truth.pred
    required = [i for i in range(len(names)) if truth.f >> i & 1 or any(p >> i & 1 for p in pred)]
    req_mask = sum(1 << i for i in required)
    completions: dict[int, int] = {}

    def ways(done: int) -> int:  # orders of the remaining required items that keep every order
        if done == req_mask:
            return 1
        if done not in completions:
            completions[done] = sum(ways(done | 1 << x) for x in _ready(done))
        return completions[done]

    def _ready(done: int) -> list[int]:
        return [x for x in required if not done >> x & 1 and pred[x] & req_mask & ~done == 0]

    done, events = 0, []
    while done != req_mask:
        options = _ready(done)
        weights = np.array([ways(done | 1 << x) for x in options], dtype=float)
        x = options[int(rng.choice(len(options), p=weights / weights.sum()))]
        events.append(names[x])
        done |= 1 << x
    return rollout(domain, tuple(events), rng)


def _iou(a: set[tuple[str, ...]], b: set[tuple[str, ...]]) -> float:
    union = len(a | b)
    return 1.0 if union == 0 else len(a & b) / union


def _step(kind: str, post: ExactPosterior, truth: list[Clause], seconds: float) -> _Step:
    best = map_formula(post)
    return _Step(kind, post.entropy() + 0.0, expected_similarity(post, truth),
                 _iou(truth_tokens(best.formula.clauses(post.prior)), truth_tokens(truth)), best.text, seconds)


def simulate_exact_run(settings: ExperimentSettings, run: int) -> list[list[Any]]:
    """All rows of one run, as ``simulate.simulate_run`` writes them."""
    streams = np.random.SeedSequence([settings.seed, run]).spawn(4 + len(PROTOCOLS))
    truth_rng, demo_rng = np.random.default_rng(streams[0]), np.random.default_rng(streams[1])
    domain, prior = _start(settings.n_waypoints, settings.n_threats, settings.prior)
    voc = prior.prior.vocabulary
    truth = _truth(prior, truth_rng)
    truth_clauses = truth.clauses(prior.prior)
    finals = {settings.n_demonstrations + n for n in settings.n_query}

    def accepts(events: tuple[str, ...]) -> bool:
        return truth.within(voc.of_events(events))

    def tested(post: ExactPosterior, n_executions: int) -> int | None:
        if not settings.test_success or n_executions not in finals:
            return None
        return int(accepts(best_execution(post, domain.propositions, "min-regret").events))

    started = time.perf_counter()
    post = prior
    shared = [_step("prior", post, truth_clauses, time.perf_counter() - started)]
    shared[0] = _with_test(shared[0], tested(post, 0))
    for _ in range(settings.n_demonstrations):
        demo = _demonstration(domain, prior, truth, demo_rng)
        started = time.perf_counter()
        post = post.observe(Datum(voc.of_trace(demo.trace), True))
        shared.append(_with_test(_step("demonstration", post, truth_clauses, time.perf_counter() - started),
                                 tested(post, len(shared))))
    rows: list[list[Any]] = []
    truth_text = truth.text(prior.prior)
    for k, protocol in enumerate(PROTOCOLS):
        learner_rng = np.random.default_rng(streams[3 + k])
        teacher_rng = np.random.default_rng(streams[3 + k] if protocol == "batch" else streams[2])
        steps = list(shared)
        belief = post
        for j in range(settings.max_n_query):
            started = time.perf_counter()
            if protocol == "batch":
                demo = _demonstration(domain, prior, truth, teacher_rng)
                learner_started = time.perf_counter()
                belief = belief.observe(Datum(voc.of_trace(demo.trace), True))
                seconds = time.perf_counter() - learner_started
                kind = "demonstration"
            else:
                if protocol == "active":
                    events = best_execution(belief, domain.propositions, "active",
                                            seed=int(learner_rng.integers(2**31))).events
                else:
                    events = random_events(domain, learner_rng)
                chosen = time.perf_counter()
                verdict = accepts(events)
                if settings.noise > 0 and teacher_rng.random() < settings.noise:
                    verdict = not verdict
                updating = time.perf_counter()
                belief = belief.observe(Datum(voc.of_events(events), verdict))
                seconds = (chosen - started) + (time.perf_counter() - updating)
                kind = "query"
            n_exec = settings.n_demonstrations + 1 + j
            steps.append(_with_test(_step(kind, belief, truth_clauses, seconds), tested(belief, n_exec)))
        rows.extend(protocol_rows(settings, run, protocol, truth_text, steps))
    return rows


def _with_test(step: _Step, result: int | None) -> _Step:
    return _Step(step.kind, step.entropy, step.similarity, step.map_similarity, step.map_formula, step.seconds,
                 result)
