"""Prior mass within many constraints by clause count: each group of equal antecedent sets by the cheaper DP.

The masses by clause count are a property of the prior and the constraint alone, so they are memoised
per prior: a search scores a prefix's children against every data pattern, the next search (after
one more datum) meets them with the old patterns again, and the test plans repeat the last search.
"""

from __future__ import annotations

import threading

import numpy as np

from .batch import Batch
from .chains import ChainPrior, TokenWeights, _mass, _times_extra
from .relabel import antecedents_first, renumber, renumber_tokens
from .tails import antecedents, group_mass

CHUNK_BYTES = 48 << 20  # per DP call: the tails DP's tables grow as 2^|A| (|A| + 1) L
MEMO_ROWS = 1 << 16  # over all priors, then all forgotten: at most about 55 MB (76 coefficients a row at n = 10)

_MEMO: dict[ChainPrior, dict[bytes, np.ndarray]] = {}
_LOCK = threading.Lock()


def clear_memo() -> None:
    """Forget every memoised prior mass (benchmarks time cold searches)."""
    with _LOCK:
        _MEMO.clear()


def _rows(tokens: TokenWeights | None, rows: np.ndarray) -> TokenWeights | None:
    if tokens is None:
        return None
    return TokenWeights(tokens.g[rows], tokens.f[rows], tokens.pair[rows], tokens.g_extra[rows])


def _with_extras(prior: ChainPrior, without: np.ndarray, g_extra: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Masses with the threats' G clauses multiplied in, from masses computed with none of them allowed."""
    m = len(prior.vocabulary.extra)
    if m == 0:
        return without[rows]
    qg = prior.p_forbid
    scale = (1 - qg) ** m
    if scale == 0.0:  # every threat forbidden for sure: no row without them has mass
        raise ValueError(f"p_forbid {qg} leaves no formula without a threat's G clause; expected p_forbid < 1")
    base = without[rows] / scale  # the polynomial before the threats' factors
    return _times_extra(prior, g_extra, base[..., : base.shape[-1] - m])


def prior_mass(prior: ChainPrior, batch: Batch, by_blocks: bool = False,
               tokens: TokenWeights | None = None) -> np.ndarray:
    """Z[M, N] (or Z[M, k, N] by block count k): prior mass of the formulas within each constraint; with token
    weights (one row per constraint), each formula also weighted by its similarity tokens' weights."""
    if by_blocks or tokens is not None or len(batch) == 0:
        return _prior_mass(prior, batch, by_blocks, tokens)
    keys = np.concatenate([batch.g_ok[:, None], batch.f_ok[:, None], batch.into, batch.g_extra[:, None]], axis=1)
    names = [row.tobytes() for row in keys]
    with _LOCK:
        memo = _MEMO.setdefault(prior, {})
        known = [memo.get(name) for name in names]
    missing = [i for i, row in enumerate(known) if row is None]
    out = np.empty((len(batch), prior.degree + 1))
    for i, row in enumerate(known):
        if row is not None:
            out[i] = row
    if missing:
        rows = np.array(missing)
        out[rows] = _prior_mass(prior, batch.take(rows), False, None)
        with _LOCK:
            if sum(len(table) for table in _MEMO.values()) + len(missing) > MEMO_ROWS:
                _MEMO.clear()
            _MEMO.setdefault(prior, {}).update((names[i], out[i].copy()) for i in missing)
    return out


def _prior_mass(prior: ChainPrior, batch: Batch, by_blocks: bool = False,
                tokens: TokenWeights | None = None) -> np.ndarray:
    """``prior_mass`` without the memo."""
    voc = prior.vocabulary
    n = voc.n
    K = n + 1 if by_blocks else 1
    out = np.zeros((len(batch), K, prior.degree + 1), dtype=float if tokens is None else tokens.f.dtype)
    if len(batch) == 0:
        return out if by_blocks else out[:, 0]
    if tokens is None:  # rows equal but for the extra threats (a bound that contains a pattern's data meets it
        # in the data; a child that visits a threat) share the DP, which the threats' G clauses only multiply
        keys = np.concatenate([batch.g_ok[:, None], batch.f_ok[:, None], batch.into], axis=1)
        unique, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        if unique.shape[0] < len(batch):
            inverse = inverse.reshape(-1)
            base = batch.take(first)
            no_extra = Batch(base.g_ok, base.f_ok, base.into, np.zeros_like(base.g_extra))
            once = _prior_mass(prior, no_extra, by_blocks)  # threats never forbidden: their G clauses absent
            return _with_extras(prior, once, batch.g_extra, inverse)
    full = (1 << n) - 1
    a_masks = antecedents(batch)
    if not 0.0 < prior.p_new_block < 1.0:  # one order (or none): the DP over all objects
        a_masks = np.full(len(batch), full, dtype=np.int64)
    sizes = np.array([bin(a).count("1") for a in a_masks.tolist()], dtype=np.int64)
    for nA in np.unique(sizes).tolist():
        rows = np.flatnonzero(sizes == nA)
        if nA == n:  # no tails: the DP over all objects
            step = 64 if n <= 8 else 16
            for start in range(0, rows.size, step):
                part = rows[start:start + step]
                cons = [batch.row(int(c)) for c in part]
                out[part] = _mass(prior, cons, by_blocks, _rows(tokens, part))
            continue
        # every row renumbered so that its antecedents are objects 0..nA-1: one tails DP for the whole size
        order = antecedents_first(a_masks[rows], n)
        group, forb = renumber(batch.take(rows), order, voc.forbiddable_orderable)
        weights = _rows(tokens, rows)
        if weights is not None:
            weights = renumber_tokens(weights, order)
        per_row = (1 << nA) * (nA + 2) * (2 * n + nA * (nA + 1) // 2 + 1) * 8 * 4
        step = max(1, CHUNK_BYTES // per_row)
        for start in range(0, rows.size, step):
            part = np.arange(start, min(start + step, rows.size))
            out[rows[part]] = group_mass(prior, group.take(part), (1 << nA) - 1, by_blocks, _rows(weights, part),
                                         forb[part])
    return out if by_blocks else out[:, 0]
