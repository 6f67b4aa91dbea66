"""The expected similarity E_P[L(phi, phi*)] to a ground truth, exactly, without listing formulas.

L = i / (r + t) with t the truth's token count, i the tokens a formula shares with it and r the
formula's other tokens (the authors' token sets, see ``metrics.py``; 1 when both are empty). Since
i / (r + t) = integral over u in [0, 1] of i u^(r + t - 1), the expectation is the integral of
u^(t - 1) d/dy Z(u, y) at y = 1, where Z weights every formula's posterior probability by u per
token outside the truth and y per shared token. Z is a chains DP with token weights
(``mass.prior_mass`` with token weights) and the data's inclusion-exclusion as in ``posterior.py``; the
derivative is a complex step (y = 1 + i h, exact to rounding for a polynomial), and the integrand is a
polynomial in u of degree below the number of possible tokens plus t, which Gauss-Legendre with
enough nodes integrates exactly. Only the "authors" metric is offered.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from ..clauses import Clause
from .chains import TokenWeights
from .mass import prior_mass
from .constraints import Vocabulary
from .posterior import ExactPosterior, _moebius

STEP = 1e-20
CHUNK = 512  # constraint rows per call (prior_mass splits them further by memory)


def truth_tokens(clauses: Iterable[Clause]) -> set[tuple[str, ...]]:
    """The authors' token set of a formula: ('G', x), ('F', w) for F(w) and for every a ordered before
    something, ('U', a, b) unless the formula has G(!b)."""
    clauses = list(clauses)
    forbidden = {c.first for c in clauses if c.kind == "G"}
    out: set[tuple[str, ...]] = set()
    for c in clauses:
        if c.kind == "U":
            out.add(("F", c.first))
            if c.second not in forbidden:
                out.add(("U", c.first, str(c.second)))
        else:
            out.add((c.kind, c.first))
    return out


def _weights(voc: Vocabulary, tokens: set[tuple[str, ...]], u: np.ndarray, y: complex) -> TokenWeights:
    """Token weights for each node u (rows): y for a truth token, u for any other."""
    n, names = voc.n, voc.orderable

    def pick(keys: list[tuple[str, ...]]) -> np.ndarray:
        inside = np.array([k in tokens for k in keys], dtype=bool)
        return np.where(inside[None, :], y, u[:, None].astype(complex))

    g = pick([("G", p) for p in names])
    f = pick([("F", p) for p in names])
    pair = pick([("U", a, z) for a in names for z in names]).reshape(-1, n, n)
    g_extra = pick([("G", p) for p in voc.extra]) if voc.extra else np.ones((u.size, 0), dtype=complex)
    return TokenWeights(g, f, pair, g_extra)


def _most_tokens(posterior: ExactPosterior) -> int:
    """A bound on the tokens of any formula the posterior gives weight: every one lies within its weakest
    data pattern (G and item tokens it allows, and no more orders than its chains inside the objects
    that may come first, plus a tail each, can hold)."""
    voc = posterior.prior.vocabulary
    n = voc.n
    weakest = posterior._pattern_batch().take(np.array([0]))
    first = int(np.bitwise_or.reduce(weakest.into[0])) if n else 0
    n_first = bin(first).count("1")
    g = bin(int(weakest.g_ok[0]) & voc.forbiddable_orderable).count("1") + bin(int(weakest.g_extra[0])).count("1")
    items = bin(int(weakest.f_ok[0]) | first).count("1")
    orders = min(n * (n - 1) // 2, (n_first + 1) * n_first // 2, sum(bin(int(v)).count("1") for v in weakest.into[0]))
    return g + items + orders


def expected_similarity(posterior: ExactPosterior, truth: Iterable[Clause], metric: str = "authors") -> float:
    """E_P[L(phi, truth)] under the exact posterior, for a truth given as its clauses."""
    if metric != "authors":
        raise ValueError(f"the exact learner's similarity supports the 'authors' metric only, got {metric!r}")
    voc = posterior.prior.vocabulary
    truth = list(truth)
    known = set(voc.orderable) | set(voc.forbiddable)
    unknown = sorted({p for c in truth for p in (c.first, c.second) if p is not None and p not in known})
    if unknown:
        raise ValueError(f"the ground truth names {', '.join(unknown)}, which are not propositions of this task")
    tokens = truth_tokens(truth)
    t = len(tokens)
    most = _most_tokens(posterior)
    if t == 0:
        nodes, weights, power = np.zeros(1), np.ones(1), 0
    else:
        x, w = np.polynomial.legendre.leggauss((most + t) // 2 + 1)
        nodes, weights, power = (x + 1) / 2, w / 2, t - 1
    patterns = posterior._pattern_batch()
    per = len(patterns)
    values = []
    for start in range(0, nodes.size, max(1, CHUNK // per)):
        u = nodes[start:start + max(1, CHUNK // per)]
        tw = _weights(voc, tokens, np.repeat(u, per), complex(1.0, STEP))
        z = prior_mass(posterior.prior, patterns.take(np.tile(np.arange(per), u.size)), tokens=tw)
        z = z.reshape(u.size, per, -1).transpose(1, 0, 2)
        masses = _moebius(z, len(posterior._bits)).transpose(1, 0, 2)  # (nodes, patterns, N)
        with np.errstate(divide="ignore", invalid="ignore"):
            lik = np.where(np.isfinite(posterior._log_f), np.exp(posterior._log_f - posterior.log_evidence), 0.0)
        values.append((masses * lik[None]).sum(axis=(1, 2)))
    total = np.concatenate(values)
    if t == 0:
        return float(np.clip(total[0].real, 0.0, 1.0))  # P(no token at all)
    shared = total.imag / STEP  # sum over formulas of P * i * u^r
    return float(np.clip((weights * nodes**power * shared).sum(), 0.0, 1.0))
