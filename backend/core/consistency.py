"""Teacher consistency: how probable the learner found each verdict just before it was given.

For a verdict on an execution, the probability the belief built from the teacher's own demonstrations
and earlier verdicts gave to that verdict (P(acceptable) for an accept, 1 - P(acceptable) for a reject).
A teacher's score is the mean over their verdicts: a perfect teacher's verdicts agree with what their
demonstrations implied, a teacher who flips verdicts gives improbable ones more often.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from . import session as core
from .belief import Belief
from .learner_seam import belief_after, verdict_probability
from .ltl_semantics import Trace

Labelled = tuple[Trace, bool, bool]  # (trace, acceptable, is_verdict)

# A verdict the learner gave less than this probability flags its task (docs/experiments.md, "Teacher consistency").
FLAG_BELOW = 0.01


def verdict_probabilities(prior: Belief, data: Sequence[Labelled], flip_rate: float = 0.0) -> list[float | None]:
    """Per item: the probability the belief just before it gave to its verdict (None for a demonstration)."""
    belief = prior
    out: list[float | None] = []
    for trace, acceptable, is_verdict in data:
        if is_verdict:
            p = belief.p_acceptable(trace)
            out.append(p if acceptable else 1.0 - p)
        else:
            out.append(None)
        belief = belief.observe(trace, acceptable, flip_rate if is_verdict else 0.0)
    return out


def session_verdict_probabilities(state: core.SessionState) -> tuple[list[float | None], list[float]]:
    """A session's verdict probabilities: per learning record (None for a demonstration), then per assessed test
    (against the final belief, which tests do not change); asked through the learner seam, so past five objects
    the exact learner's P(acceptable) of each trace under the belief just before its verdict."""
    c = state.config
    data = core.learning_verdicts(state)
    needed = [k for k, r in enumerate(state.learning_records) if r.kind == "query"]
    tests = [r for r in state.records if r.kind == "test" and r.acceptable is not None]
    beliefs = {k: belief_after(c.task, c.prior, c.flip_rate, data[:k]) for k in needed + ([len(data)] if tests else [])}
    learning = [None if r.kind != "query" else verdict_probability(beliefs[k], r.trace, bool(r.acceptable))
                for k, r in enumerate(state.learning_records)]
    final = [verdict_probability(beliefs[len(data)], r.trace, bool(r.acceptable)) for r in tests]
    return learning, final


def consistency_score(probabilities: Sequence[float | None]) -> float | None:
    """A teacher's consistency: the mean probability of their verdicts (None without any verdict)."""
    values = [p for p in probabilities if p is not None]
    return float(np.mean(values)) if values else None


def auc(positives: Sequence[float], negatives: Sequence[float]) -> float:
    """Area under the ROC curve: P(a positive scores above a negative), ties counting one half."""
    pos, neg = np.asarray(positives, dtype=float), np.asarray(negatives, dtype=float)
    if pos.size == 0 or neg.size == 0:
        raise ValueError("the AUC needs at least one score in each group")
    above = (pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()
    return float(above / (pos.size * neg.size))


def flagged(probabilities: Sequence[float | None]) -> bool:
    """Whether some verdict's probability was below FLAG_BELOW."""
    return any(p is not None and p < FLAG_BELOW for p in probabilities)
