"""Prior mass within constraints where few objects may precede another: chains over those, tails for the rest.

Call A the objects that some constraint of the group lets precede another object, T the others.
Within the constraint a chain's every element but the last lies in A, so a formula's chain
structure is: chains inside A without a tail, chains inside A that end in one object of T (a tail
z, allowed when every element of the chain may precede z), and the other objects of T alone.
Every object of T sits in exactly one block of its own, so k = |T| + j blocks for j tail-less
chains. The chains prior's weight k!/n! p^(k-1) (1-p)^(n-k) then needs the count j only:

- ``G[S]``: the objects of T taken one at a time, each alone or as the tail of a new chain inside
  A whose objects are S so far (sum over submasks, |T| 3^|A| polynomial products);
- ``H[S, j]``: S cut into j tail-less chains, the block holding min S taken first (3^|A| / 2);
- the mass is sum over S of G[S] H[A \\ S, j] times (|T| + j)! / (p n!).

Past data, A is the objects present in every acceptable execution: often half of them, so this is
far cheaper than the subset DP over all n objects in ``chains.py``, which gives the same numbers
(tests/core/test_exact_engine.py) and still answers when T is empty or the prior is one total order.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Sequence

import numpy as np

from .batch import Batch
from .chains import ChainPrior, TokenWeights, _levels, _pairs, _times_extra


def antecedents(batch: Batch) -> np.ndarray:
    """Per constraint, the mask of objects it lets precede some object."""
    if batch.into.shape[1] == 0:
        return np.zeros(len(batch), dtype=np.int64)
    return np.bitwise_or.reduce(batch.into, axis=1)


def forbiddable_rows(prior: ChainPrior, batch: Batch, forb: np.ndarray | None) -> np.ndarray:
    """Which objects may be forbidden, per row (M, n): given, or the vocabulary's for every row."""
    if forb is not None:
        return forb
    n = prior.vocabulary.n
    own = ((prior.vocabulary.forbiddable_orderable >> np.arange(n, dtype=np.int64)) & 1).astype(bool)
    return np.broadcast_to(own, (len(batch), n))


def element_polys(prior: ChainPrior, batch: Batch, forb: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per constraint and object the F/G polynomial (degree 2) as last of its block and as an earlier element
    (forb: which objects of each row may be forbidden, if not the vocabulary's)."""
    n = prior.vocabulary.n
    qf, qg = prior.p_eventually, prior.p_forbid
    shifts = np.arange(n, dtype=np.int64)
    g_ok = ((batch.g_ok[:, None] >> shifts) & 1).astype(bool)
    f_ok = ((batch.f_ok[:, None] >> shifts) & 1).astype(bool)
    qg_i = np.where(forbiddable_rows(prior, batch, forb), qg, 0.0)
    last = np.zeros((len(batch), n, 3))
    last[:, :, 0] = (1 - qg_i) * (1 - qf)
    last[:, :, 1] = np.where(f_ok, (1 - qg_i) * qf, 0.0) + np.where(g_ok, qg_i * (1 - qf), 0.0)
    if not prior.require_satisfiable:
        last[:, :, 2] = np.where(g_ok & f_ok, qg_i * qf, 0.0)
    ante = last.copy()
    if prior.require_satisfiable:  # an earlier element of a chain must occur: it cannot be forbidden
        ante[:, :, 1] = np.where(f_ok, (1 - qg_i) * qf, 0.0)
    return last, ante


def _times_element(phi: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Multiply (M, K, L) polynomials by per-constraint short polynomials phi (M, d), cut to length L."""
    out = poly * phi[:, None, 0:1]
    for d in range(1, phi.shape[-1]):
        out[:, :, d:] += poly[:, :, :-d] * phi[:, None, d:d + 1]
    return out


@lru_cache(maxsize=64)
def _local_masks(a_mask: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of A's objects, and for every local subset of A its mask over all objects."""
    ids = np.array([i for i in range(a_mask.bit_length()) if a_mask >> i & 1], dtype=np.int64)
    glob = np.zeros(1 << ids.size, dtype=np.int64)
    for k, i in enumerate(ids.tolist()):
        glob[1 << k: 2 << k] = glob[: 1 << k] | (1 << i)
    return ids, glob


def element_parts(prior: ChainPrior, batch: Batch, tokens: TokenWeights, forb: np.ndarray | None = None) -> np.ndarray:
    """parts[role, with_g, M, n, 3]: element polynomials split by whether G(i) is chosen, token-weighted
    (role 0: last of its block, 1: an earlier element, whose item token is always there); as
    ``chains._element_parts`` for a batch."""
    n, M = prior.vocabulary.n, len(batch)
    qf, qg = prior.p_eventually, prior.p_forbid
    shifts = np.arange(n, dtype=np.int64)
    f_ok = ((batch.f_ok[:, None] >> shifts) & 1).astype(bool)
    forb = forbiddable_rows(prior, batch, forb)
    g_ok = ((batch.g_ok[:, None] >> shifts) & 1).astype(bool) & forb
    parts = np.zeros((2, 2, M, n, 3), dtype=tokens.f.dtype)
    for role in (0, 1):
        for f_on in (False, True):
            for g_on in (False, True):
                if prior.require_satisfiable and g_on and (f_on or role == 1):
                    continue
                w = (qf if f_on else 1 - qf) * np.where(forb, qg if g_on else 1 - qg, 1.0)
                ok = np.ones((M, n), dtype=bool)
                if f_on:
                    ok &= f_ok
                if g_on:
                    ok &= g_ok
                tok = np.ones((M, n), dtype=tokens.f.dtype)
                if f_on or role == 1:
                    tok = tok * tokens.f
                if g_on:
                    tok = tok * tokens.g
                parts[role, int(g_on), :, :, int(f_on) + int(g_on)] += np.where(ok, w * tok, 0.0)
    return parts


def _pair_weights(tokens: TokenWeights | None, ids: np.ndarray, z: int, M: int) -> np.ndarray | None:
    """PF[M, α] = product over a in α (a subset of A, local indices) of the order token (a, z)'s weight."""
    if tokens is None:
        return None
    out = np.ones((M, 1 << ids.size), dtype=tokens.pair.dtype)
    for k, a in enumerate(ids.tolist()):
        out[:, 1 << k: 2 << k] = out[:, : 1 << k] * tokens.pair[:, a, z][:, None]
    return out


def _chain_orders(roles: np.ndarray, into: np.ndarray, ids: np.ndarray, glob: np.ndarray,
                  tokens: TokenWeights | None) -> tuple[np.ndarray, np.ndarray]:
    """chain[M, α], block[M, α]: valid orders of each subset α of A, every element an earlier one (chain) or the
    last in the last role (block), weighted by the elements' F/G polynomials (degree <= 2|α|).

    roles[role, with_g, M, n, 3] (role 0 last, 1 earlier); with token weights, the order tokens into an
    element count when it is not forbidden (with_g 0); without, with_g 0 holds the whole polynomial."""
    M, nA = into.shape[0], ids.size
    L = (roles.shape[-1] - 1) * nA + 1
    chain = np.zeros((M, 1 << nA, L), dtype=roles.dtype)
    block = np.zeros((M, 1 << nA, L), dtype=roles.dtype)
    chain[:, 0, 0] = 1.0
    levels = _levels(nA)
    pf = [_pair_weights(tokens, ids, int(z), M) for z in ids]
    for r in range(1, nA + 1):
        sets = levels[r]
        for z in range(nA):
            has = sets[(sets >> z) & 1 == 1]
            rest = has ^ (1 << z)
            zg = int(ids[z])
            valid = (glob[rest][None, :] & ~into[:, zg][:, None]) == 0
            src = chain[:, rest, :] * valid[:, :, None]
            weights = pf[z]
            paired = src if weights is None else src * weights[:, rest][:, :, None]
            for target, role in ((chain, 1), (block, 0)):
                target[:, has, :] += _times_element(roles[role, 0, :, zg, :], paired)
                if weights is not None:
                    target[:, has, :] += _times_element(roles[role, 1, :, zg, :], src)
    return chain, block


@lru_cache(maxsize=512)
def _block_pairs(nA: int, s: int, b: int, first_only: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """For every set S of size s: its submasks B of size b (holding min S if first_only) and S minus B, flat,
    and how many each S has."""
    S, B, R, per = _pairs(nA, s, b)
    if not first_only:
        return B, R, per
    keep = (B & (S & -S)) != 0
    return B[keep], R[keep], math.comb(s - 1, b - 1)


def _submask_products(read: np.ndarray, writes: Sequence[np.ndarray], weights: Sequence[np.ndarray], nA: int,
                      first_only: bool, block_scale: list[float], block_shift: list[int],
                      read_degree: list[int], weight_degree: list[int], read_width: list[int] | None = None) -> None:
    """writes[v][S] += sum over non-empty α within S (holding min S if first_only) of read[S \\ α] * weights[v][α].

    read and the writes (M, 2^nA, *mid, L) may be views of one table: level by level, a set reads only
    smaller ones, so a recursion is written in place. α's polynomials (weights[v], (M, 2^nA, Lw), of degree
    at most weight_degree[|α|]) are scaled by block_scale[|α|] and shifted by block_shift[|α|] degrees; rows
    of read for sets of size r have degree at most read_degree[r]. Products past degree L - 1 are dropped
    (the callers' L bounds every formula's clause count, so they are zero). Several weights share one
    gather of read. With one mid axis, read_width[r] (if given) says how many of its leading entries can be
    non-zero for sets of size r (a set of r objects is cut into at most r chains).
    """
    M, L = read.shape[0], read.shape[-1]
    mid = read.shape[2:-1]
    width = int(np.prod(mid)) if mid else 1
    levels = _levels(nA)
    V = len(weights)
    Lw = weights[0].shape[-1]
    for s in range(1, nA + 1):
        sets = levels[s]
        level = np.zeros((V, M, sets.size, width, L), dtype=np.result_type(read, *weights))
        for b in range(1, s + 1):
            shift = block_shift[b]
            if shift >= L or block_scale[b] == 0.0:
                continue
            B, R, per = _block_pairs(nA, s, b, first_only)
            d_max = min(Lw, L - shift, weight_degree[b] + 1)
            LR = min(L, read_degree[s - b] + 1)
            wide = width if read_width is None else min(width, read_width[s - b])
            blk = np.concatenate([w[:, B, :d_max] for w in weights], axis=2) * block_scale[b]  # (M, pairs, V d)
            rest = read[:, R, ..., :LR] if read_width is None else read[:, R, :wide, :LR]
            rest = rest.reshape(M, sets.size, per, wide * LR)
            prod = np.matmul(blk.reshape(M, sets.size, per, V * d_max).transpose(0, 1, 3, 2), rest)
            prod = prod.reshape(M, sets.size, V, d_max, wide, LR).transpose(3, 2, 0, 1, 4, 5)
            for d in range(d_max):  # the product's coefficients: block degree d shifts the rest's up by d
                top = min(LR, L - shift - d)
                level[:, :, :, :wide, shift + d:shift + d + top] += prod[d, ..., :top]
        for v, write in enumerate(writes):
            write[:, sets] += level[v].reshape(M, sets.size, *mid, L)


def _poly_product_sum(x: np.ndarray, y: np.ndarray, length: int) -> np.ndarray:
    """sum over axis 1 of the polynomial products x[:, s] * y[:, s] (last axis: coefficients), cut to length."""
    M, _, Lx = x.shape
    Ly = y.shape[-1]
    outer = np.matmul(x.transpose(0, 2, 1), y.reshape(M, y.shape[1], -1)).reshape(M, Lx, *y.shape[2:])
    out = np.zeros((M, *y.shape[2:-1], length), dtype=np.result_type(x, y))
    for a in range(min(Lx, length)):
        top = min(Ly, length - a)
        out[..., a:a + top] += outer[:, a, ..., :top]
    return out


def group_mass(prior: ChainPrior, batch: Batch, a_mask: int, by_blocks: bool,
               tokens: TokenWeights | None = None, forb: np.ndarray | None = None) -> np.ndarray:
    """Prior mass by clause count (and block count if by_blocks) of constraints whose antecedents lie in a_mask;
    with token weights, every formula also weighted by its similarity tokens' weights (rows of tokens: rows
    of the batch); forb (M, n): which objects of each row may be forbidden, if not the vocabulary's."""
    voc = prior.vocabulary
    n, M, p = voc.n, len(batch), prior.p_new_block
    ids, glob = _local_masks(a_mask)
    nA = ids.size
    t_ids = [i for i in range(n) if not a_mask >> i & 1]
    nT = len(t_ids)
    if tokens is None:
        last, ante = element_polys(prior, batch, forb)
        roles = np.stack([last, ante])[:, None]  # with_g axis of one: the whole polynomial
        dtype = np.dtype(float)
    else:
        roles = element_parts(prior, batch, tokens, forb)
        dtype = roles.dtype
    e = 2 if roles[..., 2].any() else 1  # clauses an object brings besides its orders (F and G, or one)
    roles = roles[..., :e + 1]
    L = e * n + (nA + 1) * nA // 2 + 1
    weight_degree = [e * b for b in range(nA + 1)]  # a chain or block of b objects: e clauses each at most
    chain, block = _chain_orders(roles, batch.into, ids, glob, tokens)
    last_all = roles[0].sum(axis=0)  # (M, n, e + 1)
    full = (1 << nA) - 1
    # H: A cut into j tail-less chains
    H = np.zeros((M, 1 << nA, nA + 1, L), dtype=dtype)
    H[:, 0, 0, 0] = 1.0
    if nA:
        block_scale = [0.0] + [p * (1 - p) ** (b - 1) for b in range(1, nA + 1)]
        block_shift = [0] + [b * (b - 1) // 2 for b in range(1, nA + 1)]
        degree = [e * r + r * (r - 1) // 2 for r in range(nA + 1)]
        _submask_products(H[:, :, :-1], [H[:, :, 1:]], [block], nA, True, block_scale, block_shift, degree,
                          weight_degree, list(range(1, nA + 1)))  # j+1 chains from j, and j <= |S \ α|
    ks = nT + np.arange(nA + 1)
    scale = np.array([math.exp(math.lgamma(k + 1) - math.lgamma(n + 1)) for k in ks]) / p
    H = H * scale[None, None, :, None]
    # G: objects of T alone or as tails of chains inside A (the chain's b elements bring b more pairs), on top
    # of the tail-less chains (H, collapsed over j), or from nothing when the block count is kept
    if by_blocks:
        G = np.zeros((M, 1 << nA, L), dtype=dtype)
        G[:, 0, 0] = 1.0
    else:
        G = H.sum(axis=2)
    tail_scale = [0.0] + [p * (1 - p) ** b for b in range(1, nA + 1)]
    tail_shift = [0] + [(b + 1) * b // 2 for b in range(1, nA + 1)]
    for t, zg in enumerate(t_ids):
        degree = [e * (r + t) + (r + 1) * r // 2 for r in range(nA + 1)]
        fits = (glob[None, :] & ~batch.into[:, zg][:, None]) == 0  # α may all precede z
        body = chain * fits[:, :, None]
        tails = np.zeros_like(G)
        weights = _pair_weights(tokens, ids, zg, M)
        if weights is None:
            _submask_products(G, [tails], [body], nA, False, tail_scale, tail_shift, degree, weight_degree)
            G = _times_element(p * last_all[:, zg, :], G) + _times_element(roles[0, 0, :, zg, :], tails)
            continue
        plain = np.zeros_like(G)  # a forbidden tail drops its order tokens
        _submask_products(G, [tails, plain], [body * weights[:, :, None], body], nA, False, tail_scale, tail_shift,
                          degree, weight_degree)
        G = (_times_element(p * last_all[:, zg, :], G) + _times_element(roles[0, 0, :, zg, :], tails)
             + _times_element(roles[0, 1, :, zg, :], plain))
    if by_blocks:
        complement = full ^ np.arange(1 << nA)
        out = np.zeros((M, n + 1, L), dtype=dtype)
        out[:, nT:] = _poly_product_sum(G, H[:, complement], L)  # (M, nA + 1, L)
    else:
        out = G[:, full][:, None, :]
    return _times_extra(prior, batch.g_extra, out, tokens)
