"""The enumerated hypothesis space of a task under a prior: clause-set bitmasks with prior mass.

Hypotheses factor into an order part (a pattern of ``(!b U a)`` bits, a few hundred distinct
ones) and a unary part (G and F bits, 2^10 codes for five plus five propositions). That
factorisation lets ``weighted_acceptance`` compute sum_h w_h [execution satisfies h] for every
execution at once with a subset-sum (zeta) transform instead of a hypotheses x executions loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .clauses import popcount
from .domain import Domain, get_domain
from .executions import ExecutionGraph, execution_graph
from .priors import PriorSpec, get_prior, log2_epsilon, order_structures

LN2 = float(np.log(2.0))


@dataclass(eq=False)
class HypothesisSpace:
    """Canonical clause sets (``masks``) of a task with their log prior probabilities."""

    domain: Domain
    prior_name: str
    spec: PriorSpec
    masks: np.ndarray
    log_prior: np.ndarray
    log_epsilon: float
    nconj: np.ndarray = field(init=False)
    u_patterns: np.ndarray = field(init=False)
    u_index: np.ndarray = field(init=False)
    unary_code: np.ndarray = field(init=False)
    ll_satisfied: np.ndarray = field(init=False)
    ll_violated: np.ndarray = field(init=False)
    _ok_cache: dict[bytes, np.ndarray] = field(init=False, default_factory=dict)
    _pairs_cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = field(init=False, default_factory=dict)
    _table_index: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        space = self.domain.clause_space
        self.masks = np.ascontiguousarray(self.masks, dtype=np.uint64)
        self.nconj = popcount(self.masks)
        unary = np.uint64(space.unary_mask)
        self.unary_code = (self.masks & unary).astype(np.int64)
        self.u_patterns, u_index = np.unique(self.masks & ~unary, return_inverse=True)
        self.u_index = u_index.astype(np.int64).ravel()
        self._table_index = (self.u_index << space.n_unary) + self.unary_code  # cell of the (pattern x code) table
        # Likelihood terms depend only on Nconj (0..63): tabulate once, gather per hypothesis.
        n = np.arange(64, dtype=np.float64)
        with np.errstate(divide="ignore"):
            violated = np.where(n > 0, -np.log1p(-np.exp2(-n)), self.log_epsilon)
        self.ll_satisfied = (n * LN2)[self.nconj]
        self.ll_violated = violated[self.nconj]

    @property
    def size(self) -> int:
        """Number of hypotheses."""
        return int(self.masks.size)

    @property
    def n_unary(self) -> int:
        """Number of unary (G and F) clause bits."""
        return self.domain.clause_space.n_unary

    def find(self, mask: int) -> int:
        """Index of a clause-set mask in the space; ValueError if the prior gives it no mass."""
        hits = np.flatnonzero(self.masks == np.uint64(mask))
        if hits.size == 0:
            text = self.domain.clause_space.text_of(mask)
            raise ValueError(f"{text!r} is not in the support of prior {self.prior_name!r}")
        return int(hits[0])

    def satisfied_by(self, sat_mask: int) -> np.ndarray:
        """Boolean array: which hypotheses an execution with this satisfied-clause mask satisfies."""
        return (self.masks & ~np.uint64(sat_mask)) == 0

    def weighted_acceptance(self, weights: np.ndarray, sat_masks: np.ndarray) -> np.ndarray:
        """For each execution e: sum of weights of the hypotheses that e satisfies."""
        k = self.n_unary
        n_patterns = self.u_patterns.size
        table = np.bincount(self._table_index, weights=weights, minlength=n_patterns << k).reshape(n_patterns, 1 << k)
        for bit in range(k):  # zeta transform: table[u, c] = sum over subsets c' of c
            view = table.reshape(n_patterns, 1 << (k - 1 - bit), 2, 1 << bit)
            view[:, :, 1, :] += view[:, :, 0, :]
        sat_masks = np.asarray(sat_masks, dtype=np.uint64)
        flat, execution = self._pattern_pairs(sat_masks)
        return np.bincount(execution, weights=table.ravel()[flat], minlength=sat_masks.size)

    def _pattern_pairs(self, sat_masks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The (pattern, execution) pairs whose order clauses the execution satisfies (about 9% of all), as
        flat indices into the (pattern x unary code) table and the execution of each pair."""
        key = sat_masks.tobytes()  # exact key, as for _pattern_ok
        cached = self._pairs_cache.get(key)
        if cached is None:
            k = self.n_unary
            pattern, execution = np.nonzero(self._pattern_ok(sat_masks))
            codes = (sat_masks & np.uint64((1 << k) - 1)).astype(np.int64)
            cached = ((pattern.astype(np.int64) << k) + codes[execution], execution)
            if len(self._pairs_cache) < 16:
                self._pairs_cache[key] = cached
        return cached

    def _pattern_ok(self, sat_masks: np.ndarray) -> np.ndarray:
        """(patterns x executions) 0/1 matrix: does the execution satisfy every order clause of the pattern."""
        key = sat_masks.tobytes()  # exact key: a hash collision must not return another set's matrix
        cached = self._ok_cache.get(key)
        if cached is None:
            order_sat = sat_masks & ~np.uint64((1 << self.n_unary) - 1)
            cached = ((self.u_patterns[:, None] & ~order_sat[None, :]) == 0).astype(np.float64)
            if len(self._ok_cache) < 16:
                self._ok_cache[key] = cached
        return cached


def _satisfiable(domain: Domain, masks: np.ndarray) -> np.ndarray:
    """Which masks some execution of the domain satisfies."""
    graph: ExecutionGraph = execution_graph(domain)
    probe = HypothesisSpace(domain, "probe", PriorSpec(), masks, np.zeros(masks.size), 0.0)
    # A hypothesis is satisfiable iff some node satisfies it: test it against the down-closure
    # of the nodes' unary codes, per order pattern.
    k = probe.n_unary
    reach = np.zeros((probe.u_patterns.size, 1 << k), dtype=bool)
    ok = probe._pattern_ok(graph.sat).astype(bool)
    codes = (graph.sat & np.uint64((1 << k) - 1)).astype(np.int64)
    for u in range(probe.u_patterns.size):
        reach[u, codes[ok[u]]] = True
    for bit in range(k):  # down-closure: a code is reachable if some superset of it is
        view = reach.reshape(reach.shape[0], 1 << (k - 1 - bit), 2, 1 << bit)
        view[:, :, 0, :] |= view[:, :, 1, :]
    return reach[probe.u_index, probe.unary_code]


def build_space(domain: Domain, prior_name: str, spec: PriorSpec | None = None) -> HypothesisSpace:
    """Enumerate a prior over a domain's clause sets exactly (merging equal clause sets)."""
    spec = spec or get_prior(prior_name)
    n = len(domain.orderable)
    structures = order_structures(spec, n)
    u_masks = np.array([_pairs_mask(domain, pairs) for pairs in structures], dtype=np.uint64)
    u_logp = np.log(np.array(list(structures.values())))
    codes, code_logp = _unary_distribution(domain, spec)
    masks = (u_masks[:, None] | codes[None, :]).ravel()
    logp = (u_logp[:, None] + code_logp[None, :]).ravel()
    keep = np.isfinite(logp)
    masks, logp = masks[keep], logp[keep]
    if spec.require_satisfiable:
        sat = _satisfiable(domain, masks)
        masks, logp = masks[sat], logp[sat]
        logp = logp - np.logaddexp.reduce(logp)
    log_eps = log2_epsilon(spec, len(domain.forbiddable), n) * LN2
    return HypothesisSpace(domain, prior_name, spec, masks, logp, log_eps)


def _pairs_mask(domain: Domain, pairs: frozenset[tuple[int, int]]) -> int:
    space = domain.clause_space
    mask = 0
    for a, b in pairs:
        mask |= space.before_bit(domain.orderable[a], domain.orderable[b])
    return mask


def _unary_distribution(domain: Domain, spec: PriorSpec) -> tuple[np.ndarray, np.ndarray]:
    """All G/F codes with their log probabilities (independent inclusion of each clause)."""
    space = domain.clause_space
    bit_probs = [spec.p_forbid] * len(domain.forbiddable) + [spec.p_eventually] * len(domain.orderable)
    k = space.n_unary
    codes = np.arange(1 << k, dtype=np.uint64)
    with np.errstate(divide="ignore"):
        logp = np.zeros(1 << k)
        for bit, p in enumerate(bit_probs):
            on = ((codes >> np.uint64(bit)) & np.uint64(1)).astype(bool)
            logp += np.where(on, np.log(p), np.log1p(-p) if p < 1 else -np.inf)
    return codes, logp


@lru_cache(maxsize=16)
def get_space(task: str, prior_name: str) -> HypothesisSpace:
    """The (cached) hypothesis space of a named task under a named prior."""
    return build_space(get_domain(task), prior_name)


def explicit_space(domain: Domain, formulas: dict[str, float] | dict[int, float]) -> HypothesisSpace:
    """A small space from explicit formulas (text or masks) with given prior probabilities."""
    space = domain.clause_space
    masks = [m if isinstance(m, int) else space.mask_of_formula(m) for m in formulas]
    probs = np.array(list(formulas.values()), dtype=np.float64)
    if len(set(masks)) != len(masks):
        raise ValueError("explicit formulas must be distinct clause sets")
    if np.any(probs <= 0) or not np.isclose(probs.sum(), 1.0):
        raise ValueError(f"explicit probabilities must be positive and sum to 1, got {probs.tolist()}")
    n = len(domain.orderable)
    log_eps = log2_epsilon(PriorSpec(), len(domain.forbiddable), n) * LN2
    return HypothesisSpace(domain, "explicit", PriorSpec(), np.array(masks, dtype=np.uint64), np.log(probs), log_eps)
