"""Prior mass within many constraints by clause count: each group of equal antecedent sets by the cheaper DP."""

from __future__ import annotations

import numpy as np

from .batch import Batch
from .chains import ChainPrior, TokenWeights, _mass, _times_extra
from .tails import antecedents, group_mass

CHUNK_BYTES = 48 << 20  # per DP call: the tails DP's tables grow as 2^|A| (|A| + 1) L


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
            once = prior_mass(prior, no_extra, by_blocks)  # threats never forbidden: their G clauses absent
            return _with_extras(prior, once, batch.g_extra, inverse)
    full = (1 << n) - 1
    a_masks = antecedents(batch)
    one_order = not 0.0 < prior.p_new_block < 1.0
    if one_order:
        a_masks = np.full(len(batch), full, dtype=np.int64)
    for a_mask in np.unique(a_masks).tolist():
        rows = np.flatnonzero(a_masks == a_mask)
        nA = bin(a_mask).count("1")
        if a_mask == full:  # no tails: the DP over all objects
            step = 64 if n <= 8 else 16
            for start in range(0, rows.size, step):
                part = rows[start:start + step]
                cons = [batch.row(int(c)) for c in part]
                out[part] = _mass(prior, cons, by_blocks, _rows(tokens, part))
            continue
        per_row = (1 << nA) * (nA + 2) * (2 * n + nA * (nA + 1) // 2 + 1) * 8 * 4
        step = max(1, CHUNK_BYTES // per_row)
        for start in range(0, rows.size, step):
            part = rows[start:start + step]
            out[part] = group_mass(prior, batch.take(part), a_mask, by_blocks, _rows(tokens, part))
    return out if by_blocks else out[:, 0]
