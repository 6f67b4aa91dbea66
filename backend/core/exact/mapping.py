"""The MAP formula, exactly: a max-product version of the chains DP inside a branch and bound over the data.

The max-product DP (``_MaxDP``) gives, for a constraint C (allowed clauses) and a set R of required
clauses, the largest prior weight of a formula within C containing R, for every clause count N, and
a formula attaining it. The likelihood depends on N and on which data the formula satisfies, so a
node of the branch and bound fixes, for every datum, "satisfied" (C within its clause set),
"violated" (R holds a clause outside it) or "unknown", and its bound takes the better factor for
every unknown datum. The best node's maximiser either attains its bound (then it is the MAP: every
other node's bound is no higher) or gets a datum wrong, and the node is split on that datum into
"satisfies it" (C met with its clause set) and, for each allowed clause outside that set, "contains
this clause and none of the earlier ones" (so violates it). The children partition the node.
The DPs of the children of a split are built together (one batch axis), and memoised by (prior,
constraint, required set): a teaching session's successive beliefs ask for the same ones again.
Ties: the first maximiser found in the DP's fixed order (lowest subsets and objects first, F before
G, fewest extra G clauses by index), deterministic but not the enumerating learner's lowest index.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from collections import OrderedDict
from typing import Sequence, TypeVar

import numpy as np

from ..ltl import conj, to_text
from ..clauses import Clause
from .chains import ChainPrior, _levels, _pairs
from .constraints import Constraint, Vocabulary
from .mass import clear_memo as clear_mass_memo
from .posterior import LN2, Datum, ExactPosterior

NEG = -math.inf
_T = TypeVar("_T")
TOLERANCE = 1e-9  # on log weights: a bound attained within this is attained


@dataclass(frozen=True)
class Required:
    """Clauses a formula must contain: G and F per orderable object, orders (a before z: bit a of pred[z]), extra G."""

    g: int
    f: int
    pred: tuple[int, ...]
    g_extra: int

    @staticmethod
    def none(n: int) -> "Required":
        """No clause required."""
        return Required(0, 0, (0,) * n, 0)

    def within(self, c: Constraint) -> bool:
        """Whether every required clause is allowed by c."""
        return (self.g & ~c.g_ok) == 0 and (self.f & ~c.f_ok) == 0 and (self.g_extra & ~c.g_extra) == 0 and all(
            (p & ~a) == 0 for p, a in zip(self.pred, c.into, strict=True))


@dataclass(frozen=True)
class Formula:
    """A formula of the chains prior: its chains (tuples, earliest first), G and F sets and forbidden extras."""

    chains: tuple[tuple[int, ...], ...]
    g: int
    f: int
    g_extra: int

    @property
    def pred(self) -> tuple[int, ...]:
        """For every object z, the objects ordered before it."""
        n = sum(len(c) for c in self.chains)
        out = [0] * n
        for chain in self.chains:
            for j, z in enumerate(chain):
                out[z] = sum(1 << a for a in chain[:j])
        return tuple(out)

    @property
    def n_clauses(self) -> int:
        """Its clause count N."""
        return bin(self.g).count("1") + bin(self.f).count("1") + bin(self.g_extra).count("1") + sum(
            len(c) * (len(c) - 1) // 2 for c in self.chains)

    def within(self, c: Constraint) -> bool:
        """Whether every clause of the formula is allowed by c (for a datum's clause set: it satisfies it)."""
        return Required(self.g, self.f, self.pred, self.g_extra).within(c)

    def clauses(self, prior: ChainPrior) -> list[Clause]:
        """Its clauses, in the clause space's bit order."""
        voc = prior.vocabulary
        out = [Clause("G", p) for p in voc.forbiddable if self._forbids(voc, p)]
        out += [Clause("F", p) for i, p in enumerate(voc.orderable) if self.f >> i & 1]
        pred = self.pred
        out += [Clause("U", a, z) for i, a in enumerate(voc.orderable) for j, z in enumerate(voc.orderable)
                if pred[j] >> i & 1]
        return out

    def _forbids(self, voc: Vocabulary, p: str) -> bool:
        if p in voc.orderable:
            return bool(self.g >> voc.orderable.index(p) & 1)
        return bool(self.g_extra >> voc.extra.index(p) & 1)

    def text(self, prior: ChainPrior) -> str:
        """Canonical text (the enumerating learner's ``text_of`` of the same clause set)."""
        return to_text(conj(c.formula() for c in self.clauses(prior)))


def log_prior(prior: ChainPrior, h: Formula) -> float:
    """log prior probability of a formula (unnormalised if the prior is conditioned on satisfiability)."""
    voc, n = prior.vocabulary, prior.vocabulary.n
    p, qf, qg = prior.p_new_block, prior.p_eventually, prior.p_forbid
    k = len(h.chains)
    if p <= 0.0:
        if k != 1:
            return NEG
        out = -math.lgamma(n + 1)
    else:
        sizes = [len(c) for c in h.chains]
        if p >= 1.0 and max(sizes) > 1:
            return NEG
        out = math.lgamma(k + 1) - math.lgamma(n + 1) + (k - 1) * _log(p) + (n - k) * _log(1 - p)
    forb = voc.forbiddable_orderable
    for i in range(n):
        out += _log(qf) if h.f >> i & 1 else _log(1 - qf)
        if forb >> i & 1:
            out += _log(qg) if h.g >> i & 1 else _log(1 - qg)
    for j in range(len(voc.extra)):
        out += _log(qg) if h.g_extra >> j & 1 else _log(1 - qg)
    if prior.require_satisfiable:
        ante = sum(1 << z for c in h.chains for z in c[:-1])
        if h.g & (h.f | ante):
            return NEG
    return out


def _log(x: float) -> float:
    return math.log(x) if x > 0 else NEG


class _MaxDP:
    """Max-product (or, with ``total=True``, sum-product) chains DP for one constraint and required set.

    Log weights, -inf where impossible. ``formula`` walks the tables back: to a maximiser, or with a
    random generator (sum-product tables) to an exact draw from the prior restricted to the constraint.
    """

    chain: np.ndarray
    block: np.ndarray
    seq: np.ndarray | None
    by_k: np.ndarray
    Lc: int
    top: np.ndarray
    top_k: np.ndarray
    extra: np.ndarray
    extra_order: list[int]
    n_required_extra: int
    split: np.ndarray
    total: np.ndarray

    def __init__(self, prior: ChainPrior, con: Constraint, req: Required, total: bool = False,
                 build: bool = True) -> None:
        self.prior, self.con, self.req = prior, con, req
        self.summing = total
        self._comb = np.logaddexp if total else np.maximum
        voc = prior.vocabulary
        n = self.n = voc.n
        qf, qg = prior.p_eventually, prior.p_forbid
        forb = voc.forbiddable_orderable
        # options per object: (degree, log weight, F, G), for the last element of a block and an earlier one
        self.options: list[list[list[tuple[int, float, bool, bool]]]] = []
        for role in ("last", "ante"):
            per = []
            for i in range(n):
                opts = []
                for f_on in (False, True):
                    for g_on in (False, True):
                        if f_on and not con.f_ok >> i & 1 or g_on and not (con.g_ok >> i & 1 and forb >> i & 1):
                            continue
                        if (req.f >> i & 1 and not f_on) or (req.g >> i & 1 and not g_on):
                            continue
                        if g_on and prior.require_satisfiable and (f_on or role == "ante"):
                            continue
                        w = (qf if f_on else 1 - qf) * ((qg if g_on else 1 - qg) if forb >> i & 1 else 1.0)
                        if w > 0:
                            opts.append((int(f_on) + int(g_on), math.log(w), f_on, g_on))
                per.append(opts)
            self.options.append(per)
        self.poly = np.full((2, n, 3), NEG)
        for r in range(2):
            for i in range(n):
                for d, lw, _, _ in self.options[r][i]:
                    self.poly[r, i, d] = self._comb(self.poly[r, i, d], lw)
        if build:
            _build_many([self])

    def _append_ok(self, rest: np.ndarray, z: int) -> np.ndarray:
        return ((rest & ~self.con.into[z]) == 0) & ((self.req.pred[z] & ~rest) == 0)

    def _finish(self) -> None:
        """The extra G clauses and the totals by clause count, from the tables."""
        n, Lc = self.n, self.Lc
        if self.seq is None:
            top = np.full(Lc, NEG)
            shift = n * (n - 1) // 2
            top[shift:shift + 2 * n + 1] = self.block[(1 << n) - 1] - math.lgamma(n + 1)
            self.top, self.top_k = top, np.ones(Lc, dtype=int)
        else:
            full = self.by_k
            top = np.logaddexp.reduce(full, axis=0) if self.summing else full.max(axis=0)
            self.top, self.top_k = top, full.argmax(axis=0)
        # extras: required ones forbidden, allowed ones optional (lowest index first)
        m = len(self.prior.vocabulary.extra)
        qg = self.prior.p_forbid
        req_e = [j for j in range(m) if self.req.g_extra >> j & 1]
        opt_e = [j for j in range(m) if self.con.g_extra >> j & 1 and not self.req.g_extra >> j & 1]
        self.extra_order = req_e + opt_e
        self.extra = np.full(m + 1, NEG)
        if all(self.con.g_extra >> j & 1 for j in req_e) and (not req_e or qg > 0):
            for e in range(len(req_e), len(req_e) + len(opt_e) + 1):
                if e > 0 and qg <= 0:
                    break
                self.extra[e] = (e * _log(qg) if e else 0.0) + ((m - e) * _log(1 - qg) if m - e else 0.0)
                if self.summing:
                    self.extra[e] += math.log(math.comb(len(opt_e), e - len(req_e)))
        self.n_required_extra = len(req_e)
        total = np.full(self.prior.degree + 1, NEG)
        self.split = np.zeros(self.prior.degree + 1, dtype=int)
        for e in range(m + 1):
            if self.extra[e] == NEG:
                continue
            cand = self.top + self.extra[e]
            seg = total[e:e + Lc]
            if self.summing:
                seg[:] = np.logaddexp(seg, cand)
                continue
            better = cand > seg
            seg[better] = cand[better]
            self.split[e:e + Lc][better] = e
        self.total = total

    def _block_weight(self, b: int) -> float:
        p = self.prior.p_new_block
        return _log(p) + (b - 1) * _log(1 - p) if b > 1 else _log(p)

    def _pick(self, cands: list[tuple[float, _T]], rng: np.random.Generator | None) -> _T:
        """The first maximiser, or (with rng) a draw in proportion to exp(value)."""
        values = np.array([v for v, _ in cands])
        if rng is None:
            return cands[int(values.argmax())][1]
        w = np.exp(values - values.max())
        return cands[int(rng.choice(len(cands), p=w / w.sum()))][1]

    def formula(self, N: int, rng: np.random.Generator | None = None) -> Formula:
        """A formula of N clauses attaining ``total[N]`` (or, with rng on summing tables, drawn given N)."""
        n = self.n
        Lc = self.Lc
        m = len(self.extra) - 1
        if rng is None:
            e = int(self.split[N])
        else:
            e = self._pick([(self.top[N - e] + self.extra[e], e) for e in range(m + 1)
                            if 0 <= N - e < Lc and self.extra[e] > NEG and self.top[N - e] > NEG], rng)
        Nc = N - e
        full = (1 << n) - 1
        chains: list[tuple[int, ...]] = []
        g = f = 0
        if self.seq is None:
            parts = [(full, Nc - n * (n - 1) // 2)]
        else:
            parts = []
            if rng is None:
                k = int(self.top_k[Nc])
            else:
                k = self._pick([(float(self.by_k[j, Nc]), j) for j in range(n + 1) if self.by_k[j, Nc] > NEG], rng)
            S, deg = full, Nc
            while S:
                low = S & -S
                cands: list[tuple[float, tuple[int, int]]] = []
                sub = S ^ low
                while True:
                    B = sub | low
                    b = bin(B).count("1")
                    lw = self._block_weight(b)
                    shift = b * (b - 1) // 2
                    for d in range(2 * b + 1):
                        r = deg - shift - d
                        if r < 0 or self.block[B, d] == NEG:
                            continue
                        v = self.block[B, d] + lw + self.seq[S ^ B, k - 1, r]
                        if v > NEG:
                            cands.append((v, (B, d)))
                    if sub == 0:
                        break
                    sub = (sub - 1) & (S ^ low)
                B, d = self._pick(cands, rng)
                parts.append((B, d))
                b = bin(B).count("1")
                S, k, deg = S ^ B, k - 1, deg - b * (b - 1) // 2 - d
        for B, d in parts:
            order, gb, fb = self._order(B, d, rng)
            chains.append(order)
            g |= gb
            f |= fb
        chosen = list(self.extra_order[:e])
        if rng is not None:
            optional = self.extra_order[self.n_required_extra:]
            picked = rng.choice(len(optional), e - self.n_required_extra, replace=False)
            chosen = self.extra_order[:self.n_required_extra] + [optional[int(i)] for i in picked]
        g_extra = sum(1 << j for j in chosen)
        return Formula(tuple(chains), g, f, g_extra)

    def _order(self, B: int, d: int, rng: np.random.Generator | None) -> tuple[tuple[int, ...], int, int]:
        """A maximising (or drawn) order of block B with element degree d, and its G and F sets."""
        order: list[int] = []
        g = f = 0
        role = 0
        while B:
            cands: list[tuple[float, tuple[int, tuple[int, float, bool, bool]]]] = []
            for z in range(self.n):
                if not B >> z & 1:
                    continue
                rest = B ^ (1 << z)
                if not self._append_ok(np.array([rest]), z)[0]:
                    continue
                for opt in self.options[role][z]:
                    if opt[0] <= d and self.chain[rest, d - opt[0]] > NEG:
                        cands.append((self.chain[rest, d - opt[0]] + opt[1], (z, opt)))
            z, opt = self._pick(cands, rng)
            order.append(z)
            f |= int(opt[2]) << z
            g |= int(opt[3]) << z
            B, d, role = B ^ (1 << z), d - opt[0], 1
        return tuple(reversed(order)), g, f


def _build_many(dps: Sequence[_MaxDP]) -> None:
    """Fill the tables of DPs over the same prior and kind (max or sum) at once, one batch axis over them."""
    first = dps[0]
    n, M = first.n, len(dps)
    comb = first._comb
    L = 2 * n + 1
    poly = np.stack([dp.poly for dp in dps])  # (M, 2, n, 3)
    into = np.array([dp.con.into for dp in dps], dtype=np.int64).reshape(M, n)
    pred = np.array([dp.req.pred for dp in dps], dtype=np.int64).reshape(M, n)
    chain = np.full((M, 1 << n, L), NEG)
    block = np.full((M, 1 << n, L), NEG)
    chain[:, 0, 0] = 0.0
    for r in range(1, n + 1):
        sets = _levels(n)[r]
        for z in range(n):
            has = sets[(sets >> z) & 1 == 1]
            rest = has ^ (1 << z)
            ok = ((rest[None, :] & ~into[:, z][:, None]) == 0) & ((pred[:, z][:, None] & ~rest[None, :]) == 0)
            src = np.where(ok[:, :, None], chain[:, rest], NEG)
            for target, role in ((chain, 1), (block, 0)):
                cand = np.full((M, has.size, L), NEG)
                for d in range(3):
                    w = poly[:, role, z, d]
                    if (w > NEG).any():
                        cand[:, :, d:] = comb(cand[:, :, d:], src[:, :, :L - d] + w[:, None, None])
                target[:, has] = comb(target[:, has], cand)
    all_sets = np.arange(1 << n)
    closed = np.ones((M, 1 << n), dtype=bool)
    for a in range(n):
        succ = ((pred >> a) & 1) * (np.int64(1) << np.arange(n, dtype=np.int64))[None, :]
        succ_mask = succ.sum(axis=1)
        closed &= ((all_sets[None, :] >> a) & 1 == 0) | ((succ_mask[:, None] & ~all_sets[None, :]) == 0)
    block[~closed] = NEG
    p = first.prior.p_new_block
    Lc = n * (n - 1) // 2 + L
    seq_all = None
    by_k = None
    if p > 0.0:
        seq_all = np.full((M, 1 << n, n + 1, Lc), NEG)
        seq_all[:, 0, 0, 0] = 0.0
        for s in range(1, n + 1):  # every S of size s, over its blocks B that hold the lowest member of S
            sets = _levels(n)[s]
            level = np.full((M, sets.size, n + 1, Lc), NEG)
            for b in range(1, s + 1):
                lw = first._block_weight(b)
                if lw == NEG:
                    continue
                S_all, B_all, R_all, _ = _pairs(n, s, b)
                keep = (B_all & (S_all & -S_all)) != 0
                B, R = B_all[keep], R_all[keep]
                per = B.size // sets.size
                shift = b * (b - 1) // 2
                for d in range(2 * b + 1):
                    v = block[:, B, d]
                    if not (v > NEG).any():
                        continue
                    off = shift + d
                    cand = seq_all[:, R, :-1, :Lc - off] + (v + lw)[:, :, None, None]
                    cand = cand.reshape(M, sets.size, per, n, Lc - off)
                    cand = np.logaddexp.reduce(cand, axis=2) if first.summing else cand.max(axis=2)
                    level[:, :, 1:, off:] = comb(level[:, :, 1:, off:], cand)
            seq_all[:, sets] = level
        lk = np.array([math.lgamma(k + 1) for k in range(n + 1)])[:, None]
        by_k = seq_all[:, (1 << n) - 1] + lk - math.lgamma(n + 1) - math.log(p)
    for i, dp in enumerate(dps):
        dp.chain, dp.block, dp.Lc = chain[i], block[i], Lc
        dp.seq = None if seq_all is None else seq_all[i]
        if by_k is not None:
            dp.by_k = by_k[i]
        dp._finish()


@dataclass(frozen=True)
class MapResult:
    """The MAP formula, its log posterior probability, and the number of max-product DPs the search used
    (built, or found memoised from an earlier search)."""

    formula: Formula
    log_probability: float
    text: str
    dps: int


@dataclass(frozen=True)
class _Node:
    """A node of the MAP search: its bound, the clause count attaining it, each datum's status (1 satisfied,
    0 violated, -1 unknown) and the DP's best log prior weight by clause count."""

    con: Constraint
    req: Required
    bound: float
    n_best: int
    status: tuple[int, ...]
    totals: np.ndarray


@dataclass
class _Memo:
    """What the MAP search keeps of one max-product DP: its totals, the maximisers asked for so far, and the
    tables while a maximiser is being walked back."""

    total: np.ndarray
    formulas: dict[int, Formula]
    dp: _MaxDP | None


# The max-product DP is a function of (prior, constraint, required set) alone, and successive beliefs of one
# teaching session split on the same data: their searches ask for the same few dozen DPs again and again.
MEMO_SIZE = 4096
_MEMO: OrderedDict[tuple[ChainPrior, Constraint, Required], _Memo] = OrderedDict()


def clear_memo() -> None:
    """Forget every memoised max-product DP and prior mass (benchmarks time cold searches)."""
    _MEMO.clear()
    clear_mass_memo()


def _memos(prior: ChainPrior, pairs: Sequence[tuple[Constraint, Required]]) -> list[_Memo]:
    """The memo of each pair's DP, the missing ones built together (their totals kept, not their tables)."""
    keys = [(prior, con, req) for con, req in pairs]
    missing = list(dict.fromkeys(k for k in keys if k not in _MEMO))
    dps = [_MaxDP(prior, con, req, build=False) for _, con, req in missing]
    n = prior.vocabulary.n
    step = max(1, (16 << 20) // ((1 << n) * (n + 2) * (prior.degree + 1) * 8))  # its temporaries are ~10x
    for start in range(0, len(dps), step):
        _build_many(dps[start:start + step])
    for key, dp in zip(missing, dps, strict=True):
        _MEMO[key] = _Memo(dp.total, {}, None)  # tables are megabytes: a maximiser rebuilds its DP if asked
    out = []
    for key in keys:
        _MEMO.move_to_end(key)
        out.append(_MEMO[key])
    while len(_MEMO) > MEMO_SIZE:
        _MEMO.popitem(last=False)
    return out


def _maximiser(prior: ChainPrior, con: Constraint, req: Required, N: int) -> Formula:
    """A formula of N clauses attaining the DP's total (the first in its fixed order), memoised."""
    memo = _memos(prior, [(con, req)])[0]
    if N not in memo.formulas:
        if memo.dp is None:
            memo.dp = _MaxDP(prior, con, req)
        memo.formulas[N] = memo.dp.formula(N)
        memo.dp = None
    return memo.formulas[N]


def _log_factor(d: Datum, sat: bool, N: np.ndarray, log_eps: float) -> np.ndarray:
    if d.acceptable:
        return N * LN2 if sat else np.full(N.shape, log_eps)
    if sat:
        return np.full(N.shape, log_eps)
    with np.errstate(divide="ignore"):
        return np.where(N > 0, -np.log1p(-np.exp2(-np.maximum(N, 1))), NEG)


def map_formula(posterior: ExactPosterior, max_dps: int = 10_000) -> MapResult:
    """The most probable formula under the exact posterior (ties: see the module's docstring)."""
    prior, data, log_eps = posterior.prior, posterior.data, posterior.log_epsilon
    voc = prior.vocabulary
    N = np.arange(prior.degree + 1, dtype=float)
    runs = 0

    def make(pairs: Sequence[tuple[Constraint, Required]]) -> list[_Node | None]:
        """The nodes of these (constraint, required) pairs (None: no formula)."""
        nonlocal runs
        live = [k for k, (con, req) in enumerate(pairs) if req.within(con)]
        runs += len(live)
        memos = _memos(prior, [pairs[k] for k in live])
        out: list[_Node | None] = [None] * len(pairs)
        for k, memo in zip(live, memos, strict=True):
            con, req = pairs[k]
            status = []
            bound = memo.total.copy()
            for d in data:
                if not req.within(d.satisfied):
                    s = 0  # violated
                elif _within(con, d.satisfied):
                    s = 1  # satisfied
                else:
                    s = -1
                status.append(s)
                if s >= 0:
                    bound = bound + _log_factor(d, bool(s), N, log_eps)
                else:
                    bound = bound + np.maximum(_log_factor(d, True, N, log_eps), _log_factor(d, False, N, log_eps))
            if np.isfinite(bound.max()):
                best_n = int(bound.argmax())
                out[k] = _Node(con, req, float(bound[best_n]), best_n, tuple(status), memo.total)
        return out

    def split_bounds(node: _Node, split: int) -> tuple[float, float]:
        """Upper bounds of the children that satisfy / violate the split datum, from the parent's DP (a child's
        formulas are some of the parent's, and its data statuses are at least as settled)."""
        base = node.totals.copy()
        for i, (d, s) in enumerate(zip(data, node.status, strict=True)):
            if i == split:
                continue
            if s >= 0:
                base = base + _log_factor(d, bool(s), N, log_eps)
            else:
                base = base + np.maximum(_log_factor(d, True, N, log_eps), _log_factor(d, False, N, log_eps))
        d = data[split]
        sat, violated = (float((base + _log_factor(d, ok, N, log_eps)).max()) for ok in (True, False))
        return sat, violated

    def score(h: Formula) -> float:
        n_c = np.array([float(h.n_clauses)])
        out = log_prior(prior, h)
        for d in data:
            out += float(_log_factor(d, h.within(d.satisfied), n_c, log_eps)[0])
        return out

    root = make([(voc.everything(), Required.none(voc.n))])[0]
    assert root is not None, "the prior has no formula"
    heap: list[tuple[float, int, Constraint, Required, _Node]] = []
    counter = 0
    heap.append((-root.bound, counter, voc.everything(), Required.none(voc.n), root))
    incumbent = _maximiser(prior, root.con, root.req, root.n_best)
    inc_score = score(incumbent)
    while heap and runs < max_dps:
        neg_bound, _, con, req, node = heapq.heappop(heap)
        bound, n_best, status = node.bound, node.n_best, node.status
        h = _maximiser(prior, con, req, n_best)
        if bound <= inc_score + TOLERANCE:
            break
        s_h = score(h)
        if s_h > inc_score + TOLERANCE:
            incumbent, inc_score = h, s_h
        if s_h >= bound - TOLERANCE:
            break
        # a datum the maximiser gets wrong: split on it
        nb = np.array([float(n_best)])
        split = next(i for i, (d, s) in enumerate(zip(data, status, strict=True)) if s < 0 and (
            _log_factor(d, h.within(d.satisfied), nb, log_eps)[0]
            < max(_log_factor(d, True, nb, log_eps)[0], _log_factor(d, False, nb, log_eps)[0])))
        sd = data[split].satisfied
        if_sat, if_violated = split_bounds(node, split)
        children = [(con.meet(sd), req)] if if_sat > inc_score + TOLERANCE else []
        if if_violated > inc_score + TOLERANCE:
            children += _outside(con, sd, req, voc.n)
        for (c_con, c_req), child in zip(children, make(children), strict=True):
            if child is not None and child.bound > inc_score + TOLERANCE:
                counter += 1
                heapq.heappush(heap, (-child.bound, counter, c_con, c_req, child))
    else:
        if heap and runs >= max_dps:
            raise RuntimeError(f"MAP search stopped after {runs} max-product DPs without a proof; raise max_dps")
    return MapResult(incumbent, inc_score - posterior.log_evidence, incumbent.text(prior), runs)


def _within(a: Constraint, b: Constraint) -> bool:
    """Every clause a allows, b allows."""
    return (a.g_ok & ~b.g_ok) == 0 and (a.f_ok & ~b.f_ok) == 0 and (a.g_extra & ~b.g_extra) == 0 and all(
        (x & ~y) == 0 for x, y in zip(a.into, b.into, strict=True))


def _outside(con: Constraint, sd: Constraint, req: Required, n: int) -> list[tuple[Constraint, Required]]:
    """Disjoint children covering "contains a clause allowed by con outside sd": the j-th requires the
    j-th such clause and excludes the earlier ones."""
    out = []
    g_ok, f_ok, into, g_extra = con.g_ok, con.f_ok, list(con.into), con.g_extra
    for i in range(n):
        bit = 1 << i
        if con.g_ok & bit and not sd.g_ok & bit and not req.g & bit:
            out.append((Constraint(g_ok, f_ok, tuple(into), g_extra),
                        Required(req.g | bit, req.f, req.pred, req.g_extra)))
            g_ok &= ~bit
        if con.f_ok & bit and not sd.f_ok & bit and not req.f & bit:
            out.append((Constraint(g_ok, f_ok, tuple(into), g_extra),
                        Required(req.g, req.f | bit, req.pred, req.g_extra)))
            f_ok &= ~bit
    for z in range(n):
        for a in range(n):
            bit = 1 << a
            if con.into[z] & bit and not sd.into[z] & bit and not req.pred[z] & bit:
                pred = tuple(p | bit if j == z else p for j, p in enumerate(req.pred))
                out.append((Constraint(g_ok, f_ok, tuple(into), g_extra), Required(req.g, req.f, pred, req.g_extra)))
                into[z] &= ~bit
    for j in range(con.g_extra.bit_length()):
        bit = 1 << j
        if con.g_extra & bit and not sd.g_extra & bit and not req.g_extra & bit:
            out.append((Constraint(g_ok, f_ok, tuple(into), g_extra),
                        Required(req.g, req.f, req.pred, req.g_extra | bit)))
            g_extra &= ~bit
    return out
