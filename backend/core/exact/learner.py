"""The exact learner for a domain and a named prior: build it, feed it traces, ask it questions."""

from __future__ import annotations

from typing import Sequence

from ..domain import Domain
from ..priors import get_prior, log2_epsilon
from .chains import ChainPrior
from .constraints import Vocabulary
from .posterior import LN2, Datum, ExactPosterior

SUPPORTED_STRUCTURES = ("chains", "total-order")
MIN_OBJECTS, MAX_OBJECTS = 2, 10


def chain_prior(domain: Domain, prior_name: str) -> tuple[ChainPrior, float]:
    """The chains prior of a named prior over a domain, with log epsilon (natural log)."""
    spec = get_prior(prior_name)
    if spec.structure not in SUPPORTED_STRUCTURES:
        raise ValueError(
            f"prior {prior_name!r} ({spec.structure}) has no exact factorised learner; "
            f"expected a prior of structure {' or '.join(SUPPORTED_STRUCTURES)}"
        )
    n = len(domain.orderable)
    if not MIN_OBJECTS <= n <= MAX_OBJECTS:
        raise ValueError(f"{n} orderable propositions; the exact learner takes {MIN_OBJECTS} to {MAX_OBJECTS}")
    forbiddable = domain.forbiddable if spec.p_forbid > 0 else ()
    vocabulary = Vocabulary(domain.orderable, tuple(forbiddable))
    p_new = 0.0 if spec.structure == "total-order" else spec.p_new_block
    prior = ChainPrior(vocabulary, p_new, spec.p_eventually, spec.p_forbid, spec.require_satisfiable)
    return prior, log2_epsilon(spec, len(domain.forbiddable), n) * LN2


def prior_posterior(domain: Domain, prior_name: str) -> ExactPosterior:
    """The prior as an exact posterior with no data."""
    prior, log_eps = chain_prior(domain, prior_name)
    return ExactPosterior(prior, (), log_eps)


def datum(posterior: ExactPosterior, trace: Sequence[Sequence[str]], acceptable: bool) -> Datum:
    """A labelled trace as the clauses it satisfies."""
    return Datum(posterior.prior.vocabulary.of_trace(trace), bool(acceptable))


def posterior_after(
    domain: Domain, prior_name: str, data: Sequence[tuple[Sequence[Sequence[str]], bool]]
) -> ExactPosterior:
    """The exact posterior after labelled traces (trace, acceptable)."""
    start = prior_posterior(domain, prior_name)
    for trace in (t for t, _ in data):
        domain.check_trace([list(s) for s in trace])
    items = tuple(datum(start, trace, ok) for trace, ok in data)
    return ExactPosterior(start.prior, items, start.log_epsilon)
