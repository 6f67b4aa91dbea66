"""Similarity between task formulas: intersection over union of their token sets.

Each formula becomes a token set (a mask over the clause universe). "authors" (default) is the
authors' definition (their formula_utils): G(!x) -> 'Gx', F(w) -> 'w', an order (a before b) ->
both (a, b) and 'a', and (a, b) removed when the same formula has G(!b); 'a' stays. "strict" is
this project's earlier variant: an order on a forbidden a or b is dropped together with its 'a'.
The two agree on formulas without G clauses (the synthetic domain's truths from the 2019 prior).
"""

from __future__ import annotations

import weakref

import numpy as np

from .clauses import ClauseSpace, popcount
from .hypotheses import HypothesisSpace

SIMILARITY_METRICS = ("authors", "strict")
DEFAULT_METRIC = "authors"

_EXPANDED: "weakref.WeakKeyDictionary[HypothesisSpace, dict[str, np.ndarray]]" = weakref.WeakKeyDictionary()
_SIMILARITIES: "weakref.WeakKeyDictionary[HypothesisSpace, dict[tuple[str, int], np.ndarray]]" = (
    weakref.WeakKeyDictionary()
)
_SIZES: "weakref.WeakKeyDictionary[HypothesisSpace, dict[str, np.ndarray]]" = weakref.WeakKeyDictionary()
_MAX_TRUTHS_PER_SPACE = 8


def check_metric(metric: str) -> str:
    """The metric name if known, else a ValueError naming the choices."""
    if metric not in SIMILARITY_METRICS:
        raise ValueError(f"unknown similarity metric {metric!r}; expected one of {', '.join(SIMILARITY_METRICS)}")
    return metric


def similarity(space: ClauseSpace, mask_a: int, mask_b: int, metric: str = DEFAULT_METRIC) -> float:
    """IoU of two formulas' token sets (1.0 for two empty formulas)."""
    check_metric(metric)
    a, b = space.expanded_mask(mask_a, metric), space.expanded_mask(mask_b, metric)
    union = bin(a | b).count("1")
    return 1.0 if union == 0 else bin(a & b).count("1") / union


def expanded_masks(hypotheses: HypothesisSpace, metric: str = DEFAULT_METRIC) -> np.ndarray:
    """Token-set mask of every hypothesis (vectorised, cached per space and metric)."""
    check_metric(metric)
    per_space = _EXPANDED.setdefault(hypotheses, {})
    cached = per_space.get(metric)
    if cached is not None:
        return cached
    space = hypotheses.domain.clause_space
    masks = hypotheses.masks
    forbidden = {p: (masks & np.uint64(space.g_bit(p))) != 0 for p in space.forbiddable}
    none = np.zeros(masks.size, dtype=bool)
    out = masks.copy()
    for clause in space.clauses:
        if clause.kind != "U":
            continue
        bit = np.uint64(space.bit(clause))
        present = (masks & bit) != 0
        blocked = forbidden.get(clause.second, none)
        if metric == "strict":
            blocked = blocked | forbidden.get(clause.first, none)
            gives_first = present & ~blocked
        else:
            gives_first = present
        out &= ~np.where(present & blocked, bit, np.uint64(0))
        out |= np.where(gives_first, np.uint64(space.f_bit(clause.first)), np.uint64(0))
    out.flags.writeable = False
    per_space[metric] = out
    return out


def similarities(hypotheses: HypothesisSpace, truth_mask: int, metric: str = DEFAULT_METRIC) -> np.ndarray:
    """Similarity of every hypothesis to a ground-truth clause set (cached for recent truths)."""
    per_space = _SIMILARITIES.setdefault(hypotheses, {})
    key = (check_metric(metric), truth_mask)
    cached = per_space.get(key)
    if cached is None:
        cached = _similarities(hypotheses, truth_mask, metric)
        cached.flags.writeable = False
        if len(per_space) >= _MAX_TRUTHS_PER_SPACE:
            per_space.pop(next(iter(per_space)))
        per_space[key] = cached
    return cached


def _expanded_sizes(hypotheses: HypothesisSpace, metric: str) -> np.ndarray:
    """Token-set size of every hypothesis (cached per space and metric)."""
    per_space = _SIZES.setdefault(hypotheses, {})
    cached = per_space.get(metric)
    if cached is None:
        cached = popcount(expanded_masks(hypotheses, metric))
        cached.flags.writeable = False
        per_space[metric] = cached
    return cached


def _similarities(hypotheses: HypothesisSpace, truth_mask: int, metric: str) -> np.ndarray:
    expanded = expanded_masks(hypotheses, metric)
    truth_tokens = hypotheses.domain.clause_space.expanded_mask(truth_mask, metric)
    inter = popcount(expanded & np.uint64(truth_tokens))
    union = _expanded_sizes(hypotheses, metric) + (bin(truth_tokens).count("1") - inter)  # |a| + |b| - |a & b|
    if truth_tokens:  # the union is never empty
        return inter / union
    return np.where(union == 0, 1.0, inter / np.maximum(union, 1))
