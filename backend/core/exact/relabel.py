"""Rows of a batch renumbered so that each row's antecedents are its first objects (the prior treats objects alike).

The tails DP (``tails.py``) runs once per antecedent set; renumbered, every row whose antecedent set has
the same size shares one run, so a search's many small groups become a few large ones. Only the
objects that may also be forbidden differ between objects, and they travel with each row.
"""

from __future__ import annotations

import numpy as np

from .batch import Batch
from .chains import TokenWeights


def antecedents_first(a_masks: np.ndarray, n: int) -> np.ndarray:
    """order[c, k]: the old index of row c's new object k (its antecedents ascending, then the others ascending)."""
    inside = (a_masks[:, None] >> np.arange(n, dtype=np.int64)) & 1
    return np.argsort(1 - inside, axis=1, kind="stable")


def _remap(masks: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Bitmasks over old indices as bitmasks over new ones (masks (M,) or (M, n); order (M, n))."""
    pick = order if masks.ndim == 1 else order[:, None, :]
    bits = (masks[..., None] >> pick) & 1
    return (bits << np.arange(order.shape[1], dtype=np.int64)).sum(axis=-1)


def renumber(batch: Batch, order: np.ndarray, forbiddable: int) -> tuple[Batch, np.ndarray]:
    """The batch with row c's objects renumbered by order[c], and which new objects may be forbidden (M, n)."""
    into = np.take_along_axis(batch.into, order, axis=1)
    out = Batch(_remap(batch.g_ok, order), _remap(batch.f_ok, order), _remap(into, order), batch.g_extra)
    return out, ((forbiddable >> order) & 1).astype(bool)


def renumber_tokens(tokens: TokenWeights, order: np.ndarray) -> TokenWeights:
    """Token weights with row c's objects renumbered by order[c]."""
    pair = np.take_along_axis(tokens.pair, order[:, :, None], axis=1)
    pair = np.take_along_axis(pair, order[:, None, :], axis=2)
    return TokenWeights(np.take_along_axis(tokens.g, order, axis=1), np.take_along_axis(tokens.f, order, axis=1),
                        pair, tokens.g_extra)
