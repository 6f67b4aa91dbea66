"""The enumerating learner's beliefs after a session's data, cached prefix by prefix: shared by the session
(core.session) and the learner seam (core.learner_seam), which routes the session's robot turns."""

from __future__ import annotations

from functools import lru_cache

from .belief import Belief
from .hypotheses import get_space

Trace = tuple[frozenset[str], ...]
Verdicts = tuple[tuple[Trace, bool, bool], ...]  # (trace, acceptable, is_verdict)


@lru_cache(maxsize=32)  # a 513,024-hypothesis belief is about 8 MB; the default prior's is 0.6 MB
def belief_after(task: str, prior: str, data: tuple[tuple[Trace, bool], ...]) -> Belief:
    """The belief after these labelled executions, in order (cached prefix by prefix)."""
    if not data:
        return Belief.prior(get_space(task, prior))
    trace, acceptable = data[-1]
    return belief_after(task, prior, data[:-1]).observe(trace, acceptable)


@lru_cache(maxsize=32)
def noisy_belief_after(task: str, prior: str, flip_rate: float, data: Verdicts) -> Belief:
    """The noise-aware learner's belief after (trace, acceptable, is_verdict) items, in order: verdicts
    are flipped w.p. ``flip_rate``, demonstrations never (flip_rate 0 is ``belief_after``, same cache)."""
    if flip_rate == 0.0:
        return belief_after(task, prior, tuple((trace, acceptable) for trace, acceptable, _ in data))
    if not data:
        return Belief.prior(get_space(task, prior))
    trace, acceptable, is_verdict = data[-1]
    earlier = noisy_belief_after(task, prior, flip_rate, data[:-1])
    return earlier.observe(trace, acceptable, flip_rate if is_verdict else 0.0)
