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
Ties: the first maximiser found in the DP's fixed order (lowest subsets and objects first, F before
G, fewest extra G clauses by index), deterministic but not the enumerating learner's lowest index.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from ..ltl import conj, to_text
from ..clauses import Clause
from .chains import ChainPrior, _levels, _pairs
from .constraints import Constraint, Vocabulary
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

    def __init__(self, prior: ChainPrior, con: Constraint, req: Required, total: bool = False) -> None:
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
        self._build()

    def _append_ok(self, rest: np.ndarray, z: int) -> np.ndarray:
        return ((rest & ~self.con.into[z]) == 0) & ((self.req.pred[z] & ~rest) == 0)

    def _build(self) -> None:
        n = self.n
        L = 2 * n + 1
        chain = np.full((1 << n, L), NEG)
        block = np.full((1 << n, L), NEG)
        chain[0, 0] = 0.0
        for r in range(1, n + 1):
            sets = _levels(n)[r]
            for z in range(n):
                has = sets[(sets >> z) & 1 == 1]
                rest = has ^ (1 << z)
                ok = self._append_ok(rest, z)
                src = np.where(ok[:, None], chain[rest], NEG)
                for target, role in ((chain, 1), (block, 0)):
                    cand = np.full((has.size, L), NEG)
                    for d in range(3):
                        if self.poly[role, z, d] > NEG:
                            cand[:, d:] = self._comb(cand[:, d:], src[:, :L - d] + self.poly[role, z, d])
                    target[has] = self._comb(target[has], cand)
        succ = [sum(1 << z for z in range(n) if self.req.pred[z] >> a & 1) for a in range(n)]
        all_sets = np.arange(1 << n)
        closed = np.ones(1 << n, dtype=bool)
        for a in range(n):
            closed &= ((all_sets >> a) & 1 == 0) | ((succ[a] & ~all_sets) == 0)
        block[~closed] = NEG
        self.chain, self.block = chain, block
        p = self.prior.p_new_block
        Lc = n * (n - 1) // 2 + L
        self.Lc = Lc
        if p <= 0.0:
            self.seq = None
            top = np.full(Lc, NEG)
            shift = n * (n - 1) // 2
            top[shift:shift + L] = block[(1 << n) - 1] - math.lgamma(n + 1)
            self.top, self.top_k = top, np.ones(Lc, dtype=int)
        else:
            seq = np.full((1 << n, n + 1, Lc), NEG)
            seq[0, 0, 0] = 0.0
            for s in range(1, n + 1):  # every S of size s, over its blocks B that hold the lowest member of S
                sets = _levels(n)[s]
                level = np.full((sets.size, n + 1, Lc), NEG)
                for b in range(1, s + 1):
                    lw = self._block_weight(b)
                    if lw == NEG:
                        continue
                    S_all, B_all, R_all, _ = _pairs(n, s, b)
                    keep = (B_all & (S_all & -S_all)) != 0
                    B, R = B_all[keep], R_all[keep]
                    per = B.size // sets.size
                    shift = b * (b - 1) // 2
                    for d in range(2 * b + 1):
                        v = block[B, d]
                        if not (v > NEG).any():
                            continue
                        off = shift + d
                        cand = seq[R, :-1, :Lc - off] + (v + lw)[:, None, None]
                        cand = cand.reshape(sets.size, per, n, Lc - off)
                        cand = np.logaddexp.reduce(cand, axis=1) if self.summing else cand.max(axis=1)
                        level[:, 1:, off:] = self._comb(level[:, 1:, off:], cand)
                seq[sets] = level
            self.seq = seq
            ks = np.arange(n + 1)
            lk = np.array([math.lgamma(k + 1) for k in ks])[:, None]
            full = seq[(1 << n) - 1] + lk - math.lgamma(n + 1) - math.log(p)
            self.by_k = full
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


@dataclass(frozen=True)
class MapResult:
    """The MAP formula, its log posterior probability, and the number of max-product DPs the search ran."""

    formula: Formula
    log_probability: float
    text: str
    dps: int


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

    def make(con: Constraint, req: Required) -> tuple[float, int, Formula, tuple[int, ...]] | None:
        nonlocal runs
        if not req.within(con):
            return None
        runs += 1
        dp = _MaxDP(prior, con, req)
        status = []
        bound = dp.total.copy()
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
        if not np.isfinite(bound.max()):
            return None
        best_n = int(bound.argmax())
        return float(bound[best_n]), best_n, dp.formula(best_n), tuple(status)

    def score(h: Formula) -> float:
        n_c = np.array([float(h.n_clauses)])
        out = log_prior(prior, h)
        for d in data:
            out += float(_log_factor(d, h.within(d.satisfied), n_c, log_eps)[0])
        return out

    root = make(voc.everything(), Required.none(voc.n))
    assert root is not None, "the prior has no formula"
    heap: list[tuple[float, int, Constraint, Required, tuple[float, int, Formula, tuple[int, ...]]]] = []
    counter = 0
    heap.append((-root[0], counter, voc.everything(), Required.none(voc.n), root))
    incumbent, inc_score = root[2], score(root[2])
    while heap and runs < max_dps:
        neg_bound, _, con, req, (bound, n_best, h, status) = heapq.heappop(heap)
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
        children = [(con.meet(sd), req), *_outside(con, sd, req, voc.n)]
        for c_con, c_req in children:
            child = make(c_con, c_req)
            if child is not None and child[0] > inc_score + TOLERANCE:
                counter += 1
                heapq.heappush(heap, (-child[0], counter, c_con, c_req, child))
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
