"""Exact posterior over task formulas (Bayesian specification inference), in log space.

Likelihood of one labelled execution under a hypothesis with N clauses (the authors' model):
acceptable: 2^N if the execution satisfies it, else epsilon; unacceptable: 2^N / (2^N - 1) if
the execution violates it, else epsilon (the empty formula cannot be violated). Executions are
independent, so an update adds one log-likelihood vector: incremental and exact.

The noise-aware learner (``flip_rate`` f in (0, 0.5)) assumes each verdict is the formula's truth
value flipped with probability f: a hypothesis the verdict agrees with keeps the authors' term
times (1 - f), one it contradicts gets f instead of epsilon, so one wrong verdict can no longer
rule out the truth. f = 0 is the authors' likelihood above, computed by the same code as before.
Demonstrations are never flipped (they are acceptable by definition).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Sequence

import numpy as np

from .hypotheses import HypothesisSpace
from .ltl_semantics import Trace


@dataclass(frozen=True)
class LabelledExecution:
    """A trace with the teacher's verdict: True means acceptable."""

    trace: tuple[frozenset[str], ...]
    acceptable: bool

    @staticmethod
    def of(trace: Sequence[Sequence[str]], acceptable: bool) -> "LabelledExecution":
        """Build from any sequence of states; checks the label is a real boolean."""
        if not isinstance(acceptable, (bool, np.bool_)):
            raise ValueError(f"label must be true or false, got {acceptable!r}")
        if len(trace) == 0:
            raise ValueError("a trace must have at least one state (the initial state)")
        return LabelledExecution(tuple(frozenset(s) for s in trace), bool(acceptable))


MAX_FLIP_RATE = 0.5  # exclusive: at 1/2 a verdict says nothing, above it says the opposite


def check_flip_rate(flip_rate: float, name: str = "flip rate") -> float:
    """The flip rate as a float if it is a probability in [0, 0.5), else a ValueError naming it."""
    if isinstance(flip_rate, bool) or not isinstance(flip_rate, (int, float, np.floating)) or not (
        0.0 <= flip_rate < MAX_FLIP_RATE
    ):
        raise ValueError(f"{name} must be a probability in [0, {MAX_FLIP_RATE}), got {flip_rate!r}")
    return float(flip_rate)


def log_likelihood(space: HypothesisSpace, sat_mask: int, acceptable: bool, flip_rate: float = 0.0) -> np.ndarray:
    """Log-likelihood of one labelled execution (given its satisfied-clause mask) for every hypothesis;
    ``flip_rate`` > 0 is the noise-aware likelihood of a verdict (module docstring)."""
    satisfied = space.satisfied_by(sat_mask)
    if flip_rate == 0.0:
        if acceptable:
            return np.where(satisfied, space.ll_satisfied, space.log_epsilon)
        return np.where(satisfied, space.log_epsilon, space.ll_violated)
    keep, flip = np.log1p(-flip_rate), np.log(flip_rate)
    if acceptable:
        return np.where(satisfied, keep + space.ll_satisfied, flip)
    return np.where(satisfied, flip, keep + space.ll_violated)


def likelihood_terms(space: HypothesisSpace, acceptable: bool, flip_rate: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(log-likelihood if satisfied, if violated) per hypothesis for one verdict: ``log_likelihood`` in two parts."""
    n = space.size
    if flip_rate == 0.0:
        if acceptable:
            return space.ll_satisfied, np.full(n, space.log_epsilon)
        return np.full(n, space.log_epsilon), space.ll_violated
    keep, flip = np.log1p(-flip_rate), np.log(flip_rate)
    if acceptable:
        return keep + space.ll_satisfied, np.full(n, flip)
    return np.full(n, flip), keep + space.ll_violated


@dataclass(frozen=True, eq=False)
class Belief:
    """A distribution over a hypothesis space, stored as unnormalised log weights."""

    space: HypothesisSpace
    log_weights: np.ndarray

    @staticmethod
    def prior(space: HypothesisSpace) -> "Belief":
        """The prior belief of a hypothesis space."""
        return Belief(space, space.log_prior.copy())

    def observe_mask(self, sat_mask: int, acceptable: bool, flip_rate: float = 0.0) -> "Belief":
        """The posterior after one execution with the given satisfied-clause mask and label."""
        ll = log_likelihood(self.space, sat_mask, acceptable, check_flip_rate(flip_rate))
        ll += self.log_weights  # in place: the same sums as log_weights + ll, one array fewer
        return Belief(self.space, ll)

    def observe(self, trace: Trace, acceptable: bool, flip_rate: float = 0.0) -> "Belief":
        """The posterior after one labelled execution (a verdict flipped w.p. ``flip_rate`` if > 0)."""
        self.space.domain.check_trace(list(trace))
        return self.observe_mask(self.space.domain.clause_space.sat_mask(trace), acceptable, flip_rate)

    def observe_all(self, executions: Sequence[LabelledExecution]) -> "Belief":
        """The posterior after several labelled executions, applied in order."""
        belief = self
        for execution in executions:
            belief = belief.observe(execution.trace, execution.acceptable)
        return belief

    # ------------------------------------------------------------ summaries

    @cached_property
    def probs(self) -> np.ndarray:
        """Normalised posterior probabilities."""
        shifted = self.log_weights - self.log_weights.max()
        np.exp(shifted, out=shifted)  # in place: the same values, without two more arrays of the space's size
        shifted /= shifted.sum()
        return shifted

    @cached_property
    def entropy(self) -> float:
        """Shannon entropy in nats over canonical clause sets."""
        p = self.probs
        nz = p if p.min() > 0 else p[p > 0]  # the same terms in the same order; copied only if some are 0
        terms = np.log(nz)
        terms *= nz
        return float(-terms.sum())

    @cached_property
    def map_index(self) -> int:
        """Index of the most probable hypothesis (lowest index among exact ties)."""
        return int(np.argmax(self.log_weights))

    @property
    def map_mask(self) -> int:
        """Clause-set mask of the most probable hypothesis."""
        return int(self.space.masks[self.map_index])

    def top(self, k: int) -> list[tuple[int, float]]:
        """The k most probable hypotheses as (mask, probability), most probable first."""
        if k <= 0:
            return []
        k = min(k, self.space.size)
        idx = np.argpartition(-self.log_weights, k - 1)[:k]
        idx = idx[np.lexsort((idx, -self.log_weights[idx]))]
        return [(int(self.space.masks[i]), float(self.probs[i])) for i in idx]

    def p_acceptable(self, trace: Trace) -> float:
        """Posterior probability that an execution with this trace is acceptable."""
        return self.p_acceptable_mask(self.space.domain.clause_space.sat_mask(trace))

    def p_acceptable_mask(self, sat_mask: int) -> float:
        """Posterior probability that an execution with this satisfied-clause mask is acceptable."""
        return float(self.probs[self.space.satisfied_by(sat_mask)].sum())

    def similarity(self, truth_mask: int, metric: str = "authors") -> float:
        """Expected similarity E_P[L(phi, truth)] (by default the authors' IoU of token sets)."""
        from .metrics import similarities

        # einsum, not @: BLAS splits a long dot product over threads, whose spinning took as much CPU as the
        # rest of a sweep, and whose rounding depended on the machine's thread count.
        return float(np.einsum("i,i->", self.probs, similarities(self.space, truth_mask, metric)))

    def map_similarity(self, truth_mask: int, metric: str = "authors") -> float:
        """Similarity of the MAP formula to the truth."""
        from .metrics import similarity

        return similarity(self.space.domain.clause_space, self.map_mask, truth_mask, metric)

