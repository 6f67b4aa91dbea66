"""Exact samples from the exact posterior: draw the satisfaction pattern and clause count, then a formula.

The posterior mass of (pattern v, clause count N) is known exactly (``ExactPosterior`` keeps the
Moebius-inverted masses). Given (v, N), the posterior is the prior restricted to the formulas with
exactly pattern v and N clauses. A backward walk through the sum-product tables of the constraint
"satisfies every datum of v" draws from the prior within that constraint with N clauses, and a draw
is kept when it satisfies exactly the data of v (rejection; it is exact). When the posterior dropped
the terms that violate an acceptable execution (``exact_terms`` False, at most 1e-16 of the
evidence), the samples come from that same distribution.
"""

from __future__ import annotations

import numpy as np

from .mapping import Formula, Required, _MaxDP
from .posterior import ExactPosterior

MAX_TRIES = 100_000


def sample_formulas(posterior: ExactPosterior, count: int, rng: np.random.Generator,
                    max_tries: int = MAX_TRIES) -> list[Formula]:
    """``count`` independent exact draws from the posterior."""
    if count < 0:
        raise ValueError(f"sample count must be >= 0, got {count}")
    masses = np.clip(posterior._masses(None), 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        weights = np.where(masses > 0, masses * np.exp(posterior._log_f - posterior.log_evidence), 0.0)
    flat = weights.ravel() / weights.sum()
    cons = posterior._constraints(None)
    n_obj = posterior.prior.vocabulary.n
    tables: dict[int, _MaxDP] = {}
    out = []
    for cell in rng.choice(flat.size, count, p=flat):
        t, N = divmod(int(cell), weights.shape[1])
        dp = tables.get(t)
        if dp is None:
            dp = tables[t] = _MaxDP(posterior.prior, cons[t], Required.none(n_obj), total=True)
        for _ in range(max_tries):
            h = dp.formula(N, rng)
            if all(h.within(posterior.data[i].satisfied) == bool(t >> j & 1) for j, i in enumerate(posterior._bits)):
                out.append(h)
                break
        else:
            raise RuntimeError(f"no formula with satisfaction pattern {t:b} and {N} clauses in {max_tries} draws; "
                               f"raise max_tries")
    return out
