"""Prior mass of the formulas inside a constraint, by clause count N: a subset DP over chain structures.

For the chains prior (a uniform permutation cut into blocks, a new block after each element with
probability p; F and G clauses independent) a structure of k blocks has probability
k!/n! p^(k-1) (1-p)^(n-k). Summing over ordered sequences of blocks counts each structure k! times,
so ``seq[S] = sum over non-empty B within S of w(B) seq[S \\ B]`` with w(B) = p (1-p)^(|B|-1)
x^C(|B|,2) ord(B) gives the whole sum (about 3^n polynomial products). ord(B) sums the valid orders
of the block (every pair allowed), each element weighted by its own F/G polynomial, built by
removing the last element (n 2^n). Polynomials in x count clauses, so the result is a vector over
N = 0..m+n+n(n-1)/2. With satisfiability conditioning an element that comes before another in its
block (it must occur) may not be forbidden, and no object may be both required and forbidden.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np

from .constraints import Constraint, Vocabulary


@dataclass(frozen=True)
class ChainPrior:
    """The chains prior's settings over a vocabulary."""

    vocabulary: Vocabulary
    p_new_block: float = 0.7
    p_eventually: float = 0.5
    p_forbid: float = 0.5
    require_satisfiable: bool = False

    @property
    def n_clauses(self) -> int:
        """Largest possible clause count N."""
        n = self.vocabulary.n
        return len(self.vocabulary.forbiddable) + n + n * (n - 1)

    @property
    def degree(self) -> int:
        """Length bound of the clause-count vectors minus one: 2 unary slots per object, one chain, the extras."""
        n = self.vocabulary.n
        return len(self.vocabulary.extra) + 2 * n + n * (n - 1) // 2


@lru_cache(maxsize=16)
def _levels(n: int) -> list[np.ndarray]:
    """Subsets of range(n) grouped by size."""
    sizes = np.array([bin(s).count("1") for s in range(1 << n)])
    return [np.flatnonzero(sizes == r) for r in range(n + 1)]


@lru_cache(maxsize=256)  # every (n, s, b) up to ten objects: 220, about 2 MB in all
def _pairs(n: int, s: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """For every S of size s, its submasks B of size b: (S, B, S minus B) flat, and C(s, b)."""
    sets = _levels(n)[s]
    out_s, out_b = [], []
    for S in sets.tolist():
        members = [i for i in range(n) if S >> i & 1]
        for combo in _combinations(members, b):
            out_s.append(S)
            out_b.append(sum(1 << i for i in combo))
    S_arr, B_arr = np.array(out_s, dtype=np.int64), np.array(out_b, dtype=np.int64)
    return S_arr, B_arr, S_arr ^ B_arr, math.comb(s, b)


def _combinations(items: list[int], k: int) -> list[tuple[int, ...]]:
    from itertools import combinations

    return list(combinations(items, k))


def _element_polys(prior: ChainPrior, cons: Sequence[Constraint]) -> tuple[np.ndarray, np.ndarray]:
    """Per constraint and object the F/G polynomial (degree 2) as last-of-block and as earlier element."""
    voc = prior.vocabulary
    n = voc.n
    qf, qg = prior.p_eventually, prior.p_forbid
    g_ok = np.array([[c.g_ok >> i & 1 for i in range(n)] for c in cons], dtype=bool)
    f_ok = np.array([[c.f_ok >> i & 1 for i in range(n)] for c in cons], dtype=bool)
    forb = np.array([voc.forbiddable_orderable >> i & 1 for i in range(n)], dtype=bool)
    qg_i = np.where(forb, qg, 0.0)
    last = np.zeros((len(cons), n, 3))
    last[:, :, 0] = (1 - qg_i) * (1 - qf)
    last[:, :, 1] = np.where(f_ok, (1 - qg_i) * qf, 0.0) + np.where(g_ok, qg_i * (1 - qf), 0.0)
    both = g_ok & f_ok
    last[:, :, 2] = 0.0 if prior.require_satisfiable else np.where(both, qg_i * qf, 0.0)
    ante = last.copy()
    if prior.require_satisfiable:  # an earlier element of a chain must occur: it cannot be forbidden
        ante[:, :, 1] = np.where(f_ok, (1 - qg_i) * qf, 0.0)
        ante[:, :, 2] = 0.0
    return last, ante


def _times_element(phi: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Multiply (M, K, L) polynomials by per-constraint degree-2 polynomials phi (M, 3)."""
    out = poly * phi[:, None, 0:1]
    out[:, :, 1:] += poly[:, :, :-1] * phi[:, None, 1:2]
    out[:, :, 2:] += poly[:, :, :-2] * phi[:, None, 2:3]
    return out


@dataclass(frozen=True)
class TokenWeights:
    """Per constraint, a weight for each similarity token a formula may have (see ``similarity.py``).

    ``g[M, i]`` for 'G i', ``f[M, i]`` for the item token 'i' (F(i), or i ordered before something),
    ``pair[M, a, z]`` for the order (a, z), kept only when z is not forbidden; ``g_extra[M, j]``.
    """

    g: np.ndarray
    f: np.ndarray
    pair: np.ndarray
    g_extra: np.ndarray


def _element_parts(prior: ChainPrior, cons: Sequence[Constraint], tokens: TokenWeights) -> np.ndarray:
    """parts[role, with_g, M, n, 3]: the element polynomials split by whether G(i) is chosen, token-weighted
    (role 0: last of its block, 1: an earlier element, whose item token is always there)."""
    voc = prior.vocabulary
    n, M = voc.n, len(cons)
    qf, qg = prior.p_eventually, prior.p_forbid
    forb = voc.forbiddable_orderable
    parts = np.zeros((2, 2, M, n, 3), dtype=tokens.f.dtype)
    for i in range(n):
        f_ok = np.array([c.f_ok >> i & 1 for c in cons], dtype=bool)
        g_ok = np.array([c.g_ok >> i & 1 for c in cons], dtype=bool) & bool(forb >> i & 1)
        for role in (0, 1):
            for f_on in (False, True):
                for g_on in (False, True):
                    if prior.require_satisfiable and g_on and (f_on or role == 1):
                        continue
                    w = (qf if f_on else 1 - qf) * ((qg if g_on else 1 - qg) if forb >> i & 1 else 1.0)
                    ok = np.ones(M, dtype=bool)
                    if f_on:
                        ok &= f_ok
                    if g_on:
                        ok &= g_ok
                    tok = np.ones(M, dtype=tokens.f.dtype)
                    if f_on or role == 1:
                        tok = tok * tokens.f[:, i]
                    if g_on:
                        tok = tok * tokens.g[:, i]
                    parts[role, int(g_on), :, i, int(f_on) + int(g_on)] += np.where(ok, w * tok, 0.0)
    return parts


def _pair_products(tokens: TokenWeights, n: int, z: int) -> np.ndarray:
    """PF[M, A] = product over a in A of the order token (a, z)'s weight."""
    out = np.ones((tokens.pair.shape[0], 1 << n), dtype=tokens.pair.dtype)
    idx = np.arange(1 << n)
    for a in range(n):
        has = idx[(idx >> a) & 1 == 1]
        out[:, has] = out[:, has ^ (1 << a)] * tokens.pair[:, a, z][:, None]
    return out


def _block_orders(prior: ChainPrior, cons: Sequence[Constraint], tokens: TokenWeights | None = None) -> np.ndarray:
    """ord[M, B, :2|B|+1]: each block's valid orders, weighted by its elements' F/G polynomials."""
    n = prior.vocabulary.n
    M = len(cons)
    if tokens is not None:
        return _token_block_orders(prior, cons, tokens)
    last, ante = _element_polys(prior, cons)
    into = np.array([c.into for c in cons], dtype=np.int64)  # (M, n)
    L = 2 * n + 1
    chain = np.zeros((M, 1 << n, L))  # orders of A as the earlier part of a block
    block = np.zeros((M, 1 << n, L))
    chain[:, 0, 0] = 1.0
    levels = _levels(n)
    for r in range(1, n + 1):
        sets = levels[r]
        for z in range(n):
            has = sets[(sets >> z) & 1 == 1]
            rest = has ^ (1 << z)
            valid = (rest[None, :] & ~into[:, z][:, None]) == 0  # every earlier element may precede z
            src = chain[:, rest, :] * valid[:, :, None]
            chain[:, has, :] += _times_element(ante[:, z, :], src)
            block[:, has, :] += _times_element(last[:, z, :], src)
    return block


def _token_block_orders(prior: ChainPrior, cons: Sequence[Constraint], tokens: TokenWeights) -> np.ndarray:
    """As ``_block_orders``, every formula weighted by its similarity tokens' weights."""
    n, M = prior.vocabulary.n, len(cons)
    parts = _element_parts(prior, cons, tokens)
    into = np.array([c.into for c in cons], dtype=np.int64)
    L = 2 * n + 1
    dtype = tokens.f.dtype
    chain = np.zeros((M, 1 << n, L), dtype=dtype)
    block = np.zeros((M, 1 << n, L), dtype=dtype)
    chain[:, 0, 0] = 1.0
    pf = [_pair_products(tokens, n, z) for z in range(n)]
    for r in range(1, n + 1):
        sets = _levels(n)[r]
        for z in range(n):
            has = sets[(sets >> z) & 1 == 1]
            rest = has ^ (1 << z)
            valid = (rest[None, :] & ~into[:, z][:, None]) == 0
            src = chain[:, rest, :] * valid[:, :, None]
            paired = src * pf[z][:, rest][:, :, None]  # z not forbidden: its orders are tokens
            for target, role in ((chain, 1), (block, 0)):
                target[:, has, :] += _times_element(parts[role, 0, :, z, :], paired)
                target[:, has, :] += _times_element(parts[role, 1, :, z, :], src)
    return block


def prior_mass_by_count(prior: ChainPrior, cons: Sequence[Constraint], chunk: int = 64) -> np.ndarray:
    """Z[M, N]: prior mass (unnormalised if conditioned) of the formulas within each constraint with N clauses, by
    the subset DP over all objects (``mass.prior_mass`` is the faster route; this one is its reference)."""
    out = [_mass(prior, list(cons[i:i + chunk]), False)[:, 0] for i in range(0, len(cons), chunk)]
    return np.concatenate(out, axis=0) if out else np.zeros((0, prior.degree + 1))


def _mass(prior: ChainPrior, cons: list[Constraint], by_blocks: bool, tokens: TokenWeights | None = None) -> np.ndarray:
    voc = prior.vocabulary
    n, M, p = voc.n, len(cons), prior.p_new_block
    L = n * (n - 1) // 2 + 2 * n + 1
    K, step = (n + 1, 1) if by_blocks else (1, 0)
    block = _block_orders(prior, cons, tokens)
    dtype = block.dtype
    full = (1 << n) - 1
    if p <= 0.0:  # one chain over everything
        total = np.zeros((M, K, L), dtype=dtype)
        shift = n * (n - 1) // 2
        total[:, step, shift:shift + 2 * n + 1] = block[:, full, :]
        total /= math.factorial(n)
    else:
        seq = np.zeros((M, 1 << n, K, L), dtype=dtype)
        seq[:, 0, 0, 0] = 1.0
        used = (block != 0).any(axis=(0, 2))  # blocks with a valid order under some constraint of the batch
        position = np.zeros(1 << n, dtype=np.int64)
        for level in _levels(n):
            position[level] = np.arange(level.size)
        for s in range(1, n + 1):
            sets = _levels(n)[s]
            level_sum = np.zeros((M, sets.size, K, L), dtype=dtype)  # every S of size s is written by this level only
            for b in range(1, s + 1):
                S, B, R, per = _pairs(n, s, b)
                shift = b * (b - 1) // 2
                weight = p * (1 - p) ** (b - 1)
                deg = (s - b) * (s - b - 1) // 2 + 2 * (s - b) + 1
                live = used[B]
                if live.all():
                    n_sets = R.size // per
                    rest = seq[:, R, :K - step, :deg].reshape(M, n_sets, per, (K - step) * deg)
                    blk = block[:, B, :2 * b + 1].reshape(M, n_sets, per, 2 * b + 1) * weight
                    outer = np.matmul(blk.transpose(0, 1, 3, 2), rest)  # summed over the blocks B of each set
                    outer = outer.reshape(M, n_sets, 2 * b + 1, K - step, deg)
                    for d in range(2 * b + 1):  # S[::per] lists the level's sets in order
                        level_sum[:, :, step:, shift + d:shift + d + deg] += outer[:, :, d]
                elif live.any():  # few valid blocks (data constrain them): only those pairs
                    keep = np.flatnonzero(live)
                    S_k, B_k, R_k = S[keep], B[keep], R[keep]
                    rest = seq[:, R_k, :K - step, :deg]
                    blk = block[:, B_k, :2 * b + 1] * weight
                    acc = np.zeros((M, keep.size, K - step, deg + 2 * b), dtype=dtype)
                    for d in range(2 * b + 1):
                        acc[..., d:d + deg] += blk[:, :, None, d:d + 1] * rest
                    starts = np.flatnonzero(np.r_[True, S_k[1:] != S_k[:-1]])
                    summed = np.add.reduceat(acc, starts, axis=1)
                    level_sum[:, position[S_k[starts]], step:, shift:shift + acc.shape[-1]] += summed
            seq[:, sets] = level_sum
        total = seq[:, full] / (p * math.factorial(n))
    return _times_extra(prior, np.array([c.g_extra for c in cons], dtype=np.int64), total, tokens)


def _times_extra(prior: ChainPrior, g_extra: np.ndarray, poly: np.ndarray,
                 tokens: TokenWeights | None = None) -> np.ndarray:
    """Multiply in the independent G clauses of the forbiddable-only propositions (last axis: N); g_extra[M]
    says which of them each constraint allows."""
    m = len(prior.vocabulary.extra)
    out = np.zeros((*poly.shape[:-1], prior.degree + 1), dtype=poly.dtype)
    out[..., :poly.shape[-1]] = poly
    qg = prior.p_forbid
    extra = (poly.ndim - 1) * (None,)
    for j in range(m):
        ok = ((np.asarray(g_extra, dtype=np.int64) >> j) & 1).astype(float)[(slice(None), *extra[1:])]
        if tokens is not None:
            ok = ok * tokens.g_extra[:, j][(slice(None), *extra[1:])]
        shifted = np.zeros_like(out)
        shifted[..., 1:] = out[..., :-1]
        out = out * (1 - qg) + shifted * qg * ok[..., None]
    return out
