"""The enumerated hypothesis space of a task under a prior: clause-set bitmasks with prior mass.

Hypotheses factor into an order part (a pattern of ``(!b U a)`` bits, a few hundred distinct
ones) and a unary part (G and F bits, 2^10 codes for five plus five propositions). That
factorisation lets ``weighted_acceptance`` compute sum_h w_h [execution satisfies h] for every
execution at once with a subset-sum (zeta) transform instead of a hypotheses x executions loop.
The transform runs only over the codes below some execution's code (on the dinner table, where an
object is either placed or never placed, 243 of the 1,024) with each code's patterns contiguous.
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
    _plan_cache: dict[bytes, "_ZetaPlan"] = field(init=False, default_factory=dict)
    _block_patterns: np.ndarray | None = field(init=False)

    def __post_init__(self) -> None:
        space = self.domain.clause_space
        space.check_fits_numpy()
        self.masks = np.ascontiguousarray(self.masks, dtype=np.uint64)
        self.nconj = popcount(self.masks)
        unary = np.uint64(space.unary_mask)
        self.unary_code = (self.masks & unary).astype(np.int64)
        self.u_patterns, u_index = np.unique(self.masks & ~unary, return_inverse=True)
        self.u_index = u_index.astype(np.int64).ravel()
        self._block_patterns = _block_patterns(self.u_index, self.unary_code, space.n_unary)
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
        missing = ~np.uint64(sat_mask)
        if self._block_patterns is None:
            return (self.masks & missing) == 0
        # Blocks of every unary code per pattern: a hypothesis holds iff its pattern and its code both do.
        pattern_ok = (self.u_patterns[self._block_patterns] & missing) == 0
        code_ok = (np.arange(1 << self.n_unary, dtype=np.uint64) & missing) == 0
        return (pattern_ok[:, None] & code_ok[None, :]).ravel()

    def weighted_acceptance(self, weights: np.ndarray, sat_masks: np.ndarray) -> np.ndarray:
        """For each execution e: sum of weights of the hypotheses that e satisfies."""
        sat_masks = np.asarray(sat_masks, dtype=np.uint64)
        plan = self._zeta_plan(sat_masks)
        weights = np.asarray(weights, dtype=np.float64)
        # table[r, col]: the weight of the col-th pattern with the r-th needed code, then summed over the
        # code's subsets. "+ 0.0" fills a cell exactly as summing into a zero cell does (-0.0 included).
        n_cells = plan.codes.size * self.u_patterns.size
        padded = np.empty(n_cells + 1)  # one cell more, always 0: the padding of short groups below
        padded[n_cells] = 0.0
        table = padded[:n_cells].reshape(plan.codes.size, self.u_patterns.size)
        if plan.cells is None:  # blocks of every code per pattern: the table is their transpose
            blocks = weights.reshape(-1, 1 << self.n_unary)
            np.add((blocks if plan.codes.size == blocks.shape[1] else blocks[:, plan.codes]).T, 0.0, out=table)
        elif plan.one_per_cell:
            table.fill(0.0)
            table.ravel()[plan.cells] = (weights if plan.hypotheses is None else weights[plan.hypotheses]) + 0.0
        else:
            kept = weights if plan.hypotheses is None else weights[plan.hypotheses]
            table.ravel()[:] = np.bincount(plan.cells, weights=kept, minlength=table.size)
        # Zeta transform, bit by bit in increasing order: table[c] += table[c without the bit] for every needed
        # code c with the bit. Each cell gets the same additions in the same order as over the full code table.
        if plan.steps is None:  # every code is needed: the rows with a bit come in blocks of 2^bit rows
            k = self.n_unary
            for bit in range(k):
                view = table.reshape(1 << (k - 1 - bit), 2, table.shape[1] << bit)
                view[:, 1, :] += view[:, 0, :]
        else:
            for rows, below in plan.steps:
                table[rows] += table[below]
        # Per execution, the cells of its code and of the patterns it satisfies, summed one after another in
        # increasing pattern order.
        if plan.group_bits == 0:
            return np.bincount(plan.execution, weights=table.ravel()[plan.flat], minlength=sat_masks.size)
        # flat[g, j, low]: group g's j-th pattern's cell for its execution with these low bits, padded with the
        # zero cell. Reducing over j, with a row of two or more per step, adds one j after another.
        sums = np.add.reduce(padded[plan.flat], axis=1)
        sums += 0.0  # as bincount, which starts from 0.0: a sum of -0.0 terms is 0.0
        return sums.ravel()[plan.execution]

    def _zeta_plan(self, sat_masks: np.ndarray) -> "_ZetaPlan":
        """How ``weighted_acceptance`` sums for these executions (cached by their exact masks, as _pattern_ok)."""
        key = sat_masks.tobytes()
        cached = self._plan_cache.get(key)
        if cached is None:
            cached = _ZetaPlan.build(self, sat_masks)
            if len(self._plan_cache) < 16:
                self._plan_cache[key] = cached
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


def _block_patterns(u_index: np.ndarray, unary_code: np.ndarray, n_unary: int) -> np.ndarray | None:
    """If hypotheses come in blocks of every unary code in increasing order (one order pattern per block, each
    pattern once), the pattern of each block; else None."""
    n_codes = 1 << n_unary
    if u_index.size == 0 or u_index.size % n_codes:
        return None
    codes, patterns = unary_code.reshape(-1, n_codes), u_index.reshape(-1, n_codes)
    if not (codes == np.arange(n_codes)).all() or not (patterns == patterns[:, :1]).all():
        return None
    first = patterns[:, 0].copy()
    return first if np.unique(first).size == first.size else None


@dataclass(frozen=True, eq=False)
class _ZetaPlan:
    """The index arrays of ``weighted_acceptance`` for one set of executions.

    ``codes``: the unary codes below some execution's code, ascending (the table's rows). The table's columns
    are the order patterns, in block order if the space comes in blocks (``cells`` None), else ascending with
    ``cells`` (and ``hypotheses``, None when every hypothesis is kept) saying where each hypothesis's weight goes
    in the flat table; ``one_per_cell`` if no two share a cell. ``steps``: per unary bit, the rows with that
    bit and the same rows without it (None when every code is needed: the rows are then the codes themselves).
    ``flat``: the (pattern, execution) pairs whose order clauses the execution satisfies (about 9% of all), as
    flat table indices. With ``group_bits`` 0, ``execution`` says whose each pair is, pairs in increasing
    pattern order. Else executions come in groups of 2^``group_bits`` that share their order clauses and all
    but their lowest code bits: ``flat`` is (group, j, low bits) for the group's j-th pattern in increasing
    order, padded with the zero cell after the table, and ``execution`` says each execution's place in the
    (group, low bits) sums.
    """

    codes: np.ndarray
    cells: np.ndarray | None
    one_per_cell: bool
    hypotheses: np.ndarray | None
    steps: tuple[tuple[np.ndarray, np.ndarray], ...] | None
    flat: np.ndarray
    execution: np.ndarray
    group_bits: int

    @staticmethod
    def build(space: "HypothesisSpace", sat_masks: np.ndarray) -> "_ZetaPlan":
        """The plan for these executions' satisfied-clause masks."""
        k = space.n_unary
        n_patterns = space.u_patterns.size
        exec_codes = (sat_masks & np.uint64((1 << k) - 1)).astype(np.int64)
        needed = np.zeros(1 << k, dtype=bool)  # down-closure of the executions' codes
        needed[exec_codes] = True
        for bit in range(k):
            view = needed.reshape(1 << (k - 1 - bit), 2, 1 << bit)
            view[:, 0, :] |= view[:, 1, :]
        codes = np.flatnonzero(needed)
        row = np.full(1 << k, -1, dtype=np.int64)
        row[codes] = np.arange(codes.size)
        cells: np.ndarray | None = None
        hypotheses: np.ndarray | None = None
        one_per_cell = True
        column = np.arange(n_patterns)
        if space._block_patterns is not None:
            column[space._block_patterns] = np.arange(n_patterns)
        else:
            hyp_rows = row[space.unary_code]
            if not bool((hyp_rows >= 0).all()):  # a code below no execution's: no execution satisfies it
                hypotheses = np.flatnonzero(hyp_rows >= 0)
                hyp_rows = hyp_rows[hypotheses]
            cells = hyp_rows * n_patterns + (space.u_index if hypotheses is None else space.u_index[hypotheses])
            # A cell (pattern, code) is one clause set, so distinct masks never share one: the table is then
            # filled by assignment rather than by summing (the same values, since 0.0 + w == w + 0.0).
            one_per_cell = np.unique(cells).size == cells.size
        steps = None
        if codes.size < 1 << k:
            with_bits = [codes[(codes >> bit) & 1 == 1] for bit in range(k)]
            steps = tuple((row[c], row[c ^ (1 << bit)]) for bit, c in enumerate(with_bits))
        ok = space._pattern_ok(sat_masks)
        group_bits, group = _execution_groups(sat_masks, exec_codes, k)
        if group is None:
            pattern, execution = np.nonzero(ok)
            flat = row[exec_codes[execution]] * n_patterns + column[pattern]
            return _ZetaPlan(codes, cells, one_per_cell, hypotheses, steps, flat, execution, 0)
        size = 1 << group_bits
        n_groups = sat_masks.size // size
        members = np.empty((n_groups, size), dtype=np.int64)  # members[g, low bits] = execution
        members[group, exec_codes & (size - 1)] = np.arange(sat_masks.size)
        group_ok = ok[:, members[:, 0]].T.astype(bool)  # members share their order clauses
        g_of_pair, pattern = np.nonzero(group_ok)  # by group, then increasing pattern
        rank = np.arange(g_of_pair.size) - np.searchsorted(g_of_pair, g_of_pair)  # j: the pair's place in its group
        width = max(int(group_ok.sum(axis=1).max(initial=0)), 1)
        flat = np.full((n_groups, width, size), codes.size * n_patterns, dtype=np.int64)  # the zero cell
        flat[g_of_pair, rank] = row[exec_codes[members[g_of_pair]]] * n_patterns + column[pattern][:, None]
        position = group * size + (exec_codes & (size - 1))
        return _ZetaPlan(codes, cells, one_per_cell, hypotheses, steps, flat, position, group_bits)


def _execution_groups(sat_masks: np.ndarray, exec_codes: np.ndarray, k: int) -> tuple[int, np.ndarray | None]:
    """The most low code bits b such that the executions come in groups of 2^b with the same order clauses and
    higher code bits, each low value once, with each execution's group index; (0, None) if b would be 0."""
    if sat_masks.size == 0:
        return 0, None
    order = sat_masks >> np.uint64(k)
    for bits in range(k, 0, -1):
        size = 1 << bits
        if sat_masks.size % size:
            continue
        keys = np.stack([order, (exec_codes >> bits).astype(np.uint64)], axis=1)
        _, group, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        group = group.ravel()
        if not (counts == size).all():
            continue
        low = exec_codes & (size - 1)
        if np.unique(group * size + low).size == sat_masks.size:  # each low value once per group
            return bits, group.astype(np.int64)
    return 0, None


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
    domain.clause_space.check_fits_numpy()
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
