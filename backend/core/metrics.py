"""Similarity between task formulas (the authors' intersection-over-union of clause sets).

Before comparing, each clause set is expanded: an order clause (a before b) also contributes
F(a), and order clauses that involve a G-forbidden proposition of the same set are dropped.
"""

from __future__ import annotations

import weakref

import numpy as np

from .clauses import ClauseSpace, popcount
from .hypotheses import HypothesisSpace

_EXPANDED: "weakref.WeakKeyDictionary[HypothesisSpace, np.ndarray]" = weakref.WeakKeyDictionary()
_SIMILARITIES: "weakref.WeakKeyDictionary[HypothesisSpace, dict[int, np.ndarray]]" = weakref.WeakKeyDictionary()
_MAX_TRUTHS_PER_SPACE = 8


def similarity(space: ClauseSpace, mask_a: int, mask_b: int) -> float:
    """IoU of two formulas' expanded clause sets (1.0 for two empty formulas)."""
    a, b = space.expanded_mask(mask_a), space.expanded_mask(mask_b)
    union = bin(a | b).count("1")
    return 1.0 if union == 0 else bin(a & b).count("1") / union


def expanded_masks(hypotheses: HypothesisSpace) -> np.ndarray:
    """Expanded clause set of every hypothesis (vectorised, cached per space)."""
    cached = _EXPANDED.get(hypotheses)
    if cached is not None:
        return cached
    space = hypotheses.domain.clause_space
    masks = hypotheses.masks
    forbidden = {p: (masks & np.uint64(space.g_bit(p))) != 0 for p in space.forbiddable}
    out = masks.copy()
    for clause in space.clauses:
        if clause.kind != "U":
            continue
        bit = np.uint64(space.bit(clause))
        present = (masks & bit) != 0
        blocked = np.zeros(masks.size, dtype=bool)
        for p in (clause.first, clause.second):
            if p in forbidden:
                blocked |= forbidden[p]
        out &= ~np.where(present & blocked, bit, np.uint64(0))
        out |= np.where(present & ~blocked, np.uint64(space.f_bit(clause.first)), np.uint64(0))
    _EXPANDED[hypotheses] = out
    return out


def similarities(hypotheses: HypothesisSpace, truth_mask: int) -> np.ndarray:
    """Similarity of every hypothesis to a ground-truth clause set (cached for recent truths)."""
    per_space = _SIMILARITIES.setdefault(hypotheses, {})
    cached = per_space.get(truth_mask)
    if cached is None:
        cached = _similarities(hypotheses, truth_mask)
        cached.flags.writeable = False
        if len(per_space) >= _MAX_TRUTHS_PER_SPACE:
            per_space.pop(next(iter(per_space)))
        per_space[truth_mask] = cached
    return cached


def _similarities(hypotheses: HypothesisSpace, truth_mask: int) -> np.ndarray:
    expanded = expanded_masks(hypotheses)
    truth = np.uint64(hypotheses.domain.clause_space.expanded_mask(truth_mask))
    inter = popcount(expanded & truth)
    union = popcount(expanded | truth)
    return np.where(union == 0, 1.0, inter / np.maximum(union, 1))
