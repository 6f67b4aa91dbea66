"""The exact posterior for 2 to 10 objects: the authors' likelihood through inclusion-exclusion over the data.

A formula's likelihood depends only on its clause count N and on which data it satisfies (its
satisfaction pattern v). The prior mass with N clauses of the formulas that satisfy every datum in U
is a hard-constraint partition function Z_U[N] (``mass.prior_mass``); the mass of those
satisfying exactly the data v follows by Moebius inversion over supersets of v, and the evidence is
sum over v and N of that mass times the likelihood f(N, v), summed in log space.

Epsilon terms (an acceptable execution the formula violates) are exact when every subset U is used.
When a bound on all of them together, eps^j sum_N P0[N] 2^(N (K-j)) 2^Q, is below 1e-16 of the
evidence, only the subsets that contain every acceptable execution are used (2^Q for Q unacceptable
ones): ``exact_terms`` says which was done and ``dropped_bound`` the bound.
"""

from __future__ import annotations

import math
from functools import lru_cache
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .batch import Batch
from .chains import ChainPrior
from .constraints import Constraint
from .mass import prior_mass

LN2 = math.log(2.0)
DROP_TOLERANCE = 1e-16


@dataclass(frozen=True)
class Datum:
    """A labelled execution reduced to the clauses it satisfies."""

    satisfied: Constraint
    acceptable: bool


@lru_cache(maxsize=32)
def unconstrained_mass(prior: ChainPrior) -> np.ndarray:
    """The prior's mass by clause count (a property of the prior, computed once per prior)."""
    voc = prior.vocabulary
    return prior_mass(prior, Batch.of([voc.everything()], voc.n))[0]


def _moebius(values: np.ndarray, n_bits: int) -> np.ndarray:
    """Exact-pattern masses from superset sums over n_bits (the first axis indexes subsets)."""
    out = values.copy()
    for bit in range(n_bits):
        step = 1 << bit
        view = out.reshape(-1, 2, step, *out.shape[1:])
        view[:, 0] -= view[:, 1]
    return out


@dataclass(eq=False)
class ExactPosterior:
    """P(formula | data) under the chains prior, held as weights over (satisfaction pattern, clause count)."""

    prior: ChainPrior
    data: tuple[Datum, ...]
    log_epsilon: float
    exact_terms: bool = field(init=False)
    dropped_bound: float = field(init=False)
    _bits: list[int] = field(init=False)
    _fixed: int = field(init=False)
    _weights: np.ndarray = field(init=False)
    log_evidence: float = field(init=False)

    def __post_init__(self) -> None:
        pos = [i for i, d in enumerate(self.data) if d.acceptable]
        neg = [i for i, d in enumerate(self.data) if not d.acceptable]
        length = self.prior.degree + 1
        self._fixed, self._bits = sum(1 << i for i in pos), neg
        log_f = self._log_likelihood(length)
        masses = self._masses(None)
        log_z = self._log_sum(masses, log_f)
        bound = self._eps_bound(len(pos), len(neg), length)
        self.exact_terms = not pos or bound > 0.0 and math.log(bound) > math.log(DROP_TOLERANCE) + log_z
        if self.exact_terms and pos:
            self._fixed, self._bits = 0, list(range(len(self.data)))
            self.__dict__.pop("_patterns_cache", None)
            log_f = self._log_likelihood(length)
            masses = self._masses(None)
            log_z = self._log_sum(masses, log_f)
            bound = 0.0
        self.dropped_bound = bound if pos and not self.exact_terms else 0.0
        self._log_f = log_f
        self.log_evidence = log_z

    # ------------------------------------------------------------ the pieces

    def _patterns(self) -> list[int]:
        """Data subsets (as bitmasks over data indices) indexed by subsets of the free bits."""
        out = []
        for t in range(1 << len(self._bits)):
            mask = self._fixed
            for j, i in enumerate(self._bits):
                if t >> j & 1:
                    mask |= 1 << i
            out.append(mask)
        return out

    def _constraints(self, extra: Constraint | None) -> list[Constraint]:
        """For every pattern (a subset of the free data), the meet of its data (and of extra)."""
        rows = self._pattern_batch()
        if extra is not None:
            rows = rows.meet(Batch.of([extra], self.prior.vocabulary.n))
        return [rows.row(t) for t in range(len(rows))]

    def _pattern_batch(self) -> Batch:
        """The meet of each pattern's data, one row per pattern (indexed by subsets of the free bits)."""
        cached = self.__dict__.get("_patterns_cache")
        if cached is not None:
            return cached
        voc = self.prior.vocabulary
        rows = Batch.of([voc.everything()], voc.n)
        fixed = [d for i, d in enumerate(self.data) if self._fixed >> i & 1]
        if fixed:
            rows = rows.meet(Batch.of([d.satisfied for d in fixed], voc.n).reduce())
        for i in self._bits:
            one = Batch.of([voc.everything(), self.data[i].satisfied], voc.n)
            rows = one.outer_meet(rows)  # the new bit is the highest
        self.__dict__["_patterns_cache"] = rows
        return rows

    def _masses(self, extra: Constraint | None) -> np.ndarray:
        return self._masses_many(None if extra is None else Batch.of([extra], self.prior.vocabulary.n))[0]

    def _masses_many(self, extras: Batch | None, by_blocks: bool = False) -> np.ndarray:
        """E[c, v, (k,) N]: prior mass satisfying exactly pattern v (within constraint c), by clause count."""
        patterns = self._pattern_batch()
        cons = patterns if extras is None else extras.outer_meet(patterns)
        per = len(patterns)
        z = prior_mass(self.prior, cons, by_blocks)
        z = z.reshape(len(cons) // per, per, *z.shape[1:])
        return np.moveaxis(_moebius(np.moveaxis(z, 1, 0), len(self._bits)), 0, 1)

    def _log_likelihood(self, length: int) -> np.ndarray:
        """log f(N, v) for every pattern v over the free bits and N = 0..length-1."""
        n = np.arange(length, dtype=float)
        with np.errstate(divide="ignore"):
            log_c = np.where(n > 0, -np.log1p(-np.exp2(-np.maximum(n, 1))), -np.inf)
        out = np.zeros((1 << len(self._bits), length))
        for t, mask in enumerate(self._patterns()):
            for i, d in enumerate(self.data):
                sat = bool(mask >> i & 1)
                if d.acceptable:
                    out[t] += n * LN2 if sat else self.log_epsilon
                else:
                    out[t] += self.log_epsilon if sat else log_c
        return out

    @staticmethod
    def _log_sum(masses: np.ndarray, log_f: np.ndarray) -> float:
        """log of sum over (v, N) of masses * exp(log_f), negatives from rounding clipped to zero."""
        with np.errstate(divide="ignore"):
            terms = np.log(np.clip(masses, 0.0, None)) + log_f
        top = terms.max()
        if not np.isfinite(top):
            return -math.inf
        return float(top + np.log(np.exp(terms - top).sum()))

    def _eps_bound(self, k: int, q: int, length: int) -> float:
        """Upper bound on the evidence terms in which some acceptable execution is violated."""
        if k == 0:
            return 0.0
        p0 = unconstrained_mass(self.prior)
        n = np.arange(length, dtype=float)
        terms = []
        with np.errstate(divide="ignore"):
            log_p0 = np.log(np.clip(p0, 0.0, None))
        for j in range(1, k + 1):
            inner = log_p0 + n * (k - j) * LN2
            top = inner.max()
            log_inner = top + math.log(float(np.exp(inner - top).sum()))
            terms.append(math.log(math.comb(k, j)) + j * self.log_epsilon + log_inner + q * LN2)
        return float(math.exp(min(max(terms), 700.0)) * len(terms))

    # ------------------------------------------------------------ queries of the posterior

    def p_within(self, constraints: Sequence[Constraint] | Batch) -> np.ndarray:
        """For each constraint C: the posterior probability that the formula's clauses all lie in C."""
        if len(constraints) == 0:
            return np.zeros(0)
        batch = constraints if isinstance(constraints, Batch) else Batch.of(list(constraints), self.prior.vocabulary.n)
        masses = self._masses_many(batch)
        with np.errstate(divide="ignore"):
            terms = np.log(np.clip(masses, 0.0, None)) + self._log_f[None]
        flat = terms.reshape(terms.shape[0], -1)
        top = flat.max(axis=1)
        safe = np.where(np.isfinite(top), top, 0.0)
        with np.errstate(divide="ignore"):
            log_num = safe + np.log(np.exp(flat - safe[:, None]).sum(axis=1))
        out = np.exp(log_num - self.log_evidence)
        return np.clip(np.where(np.isfinite(top), out, 0.0), 0.0, 1.0)

    def p_acceptable(self, satisfied: Constraint) -> float:
        """Posterior probability that an execution satisfying exactly these clauses is acceptable."""
        return float(self.p_within([satisfied])[0])

    def marginals(self, kinds: str = "GFU") -> dict[tuple[str, str, str | None], float]:
        """P(clause in the formula) for every template clause of the given kinds, keyed (kind, first, second)."""
        voc = self.prior.vocabulary
        keys: list[tuple[str, str, str | None]] = [("G", p, None) for p in voc.forbiddable if "G" in kinds]
        keys += [("F", p, None) for p in voc.orderable if "F" in kinds]
        keys += [("U", a, b) for a in voc.orderable for b in voc.orderable if a != b and "U" in kinds]
        absent = self.p_within([voc.without(*key) for key in keys])
        return {key: float(1.0 - a) for key, a in zip(keys, absent, strict=True)}

    def block_count_distribution(self) -> np.ndarray:
        """P(the formula's chain structure has k blocks), k = 0..n (singletons count as blocks)."""
        return self._joint().sum(axis=(0, 2))

    def _joint(self) -> np.ndarray:
        """Posterior mass over (satisfaction pattern, block count, clause count)."""
        masses = np.clip(self._masses_many(None, by_blocks=True)[0], 0.0, None)
        with np.errstate(divide="ignore", invalid="ignore"):
            return masses * np.exp(self._log_f - self.log_evidence)[:, None, :]

    def entropy(self) -> float:
        """Shannon entropy (nats) over canonical clause sets: log Z - E[log prior weight] - E[log likelihood].

        The prior weight's log is additive but for log k! (k blocks): a constant, k log(p/(1-p)),
        log k!, and N_G log(q_G/(1-q_G)) + N_F log(q_F/(1-q_F)); the counts' expectations come
        from the block-count distribution and the G and F marginals.
        """
        prior, voc = self.prior, self.prior.vocabulary
        joint = self._joint()
        log_f = np.broadcast_to(self._log_f[:, None, :], joint.shape)
        e_log_f = float(np.where(joint > 0, joint * np.where(np.isfinite(log_f), log_f, 0.0), 0.0).sum())
        n = voc.n
        k = np.arange(n + 1)
        p_k = joint.sum(axis=(0, 2))
        p = prior.p_new_block
        e_log_prior = -math.lgamma(n + 1)
        if 0.0 < p < 1.0:
            e_log_prior += -math.log(p) + n * math.log(1 - p) + float(p_k @ (k * math.log(p / (1 - p))))
            e_log_prior += float(p_k @ np.array([math.lgamma(j + 1) for j in k]))
        elif p >= 1.0:
            e_log_prior += math.lgamma(n + 1)  # all singletons: n!/n! whatever the order
        for kind, q, count in (("G", prior.p_forbid, len(voc.forbiddable)), ("F", prior.p_eventually, n)):
            if count and 0.0 < q < 1.0:
                e_log_prior += count * math.log(1 - q)
                if q != 0.5:  # the clause counts' expectations only matter when a clause changes the weight
                    expected = sum(self.marginals(kind).values())
                    e_log_prior += expected * math.log(q / (1 - q))
        return float(self.log_evidence - e_log_prior - e_log_f)

    def observe(self, datum: Datum) -> "ExactPosterior":
        """The posterior after one more labelled execution."""
        return ExactPosterior(self.prior, self.data + (datum,), self.log_epsilon)
