"""Teacher consistency as the experimenter sees it: each verdict's probability just before it was given, a task's
score, and a flag for a verdict the learner found nearly impossible (core.consistency computes the numbers).

The flag: a task is flagged when one of its verdicts (queries and tests) had a probability below FLAG_BELOW.
In simulation (docs/experiments.md, "Teacher consistency") that flags 1 perfect teacher in 200 and 109 of 200
who flip each verdict with probability 0.2; it is a reason to look at the session, not a verdict on the person.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Iterable

from ..core.consistency import FLAG_BELOW, consistency_score, flagged, session_verdict_probabilities
from .planning import session_of

__all__ = ["FLAG_BELOW", "participant_consistency", "session_consistency"]


@lru_cache(maxsize=4096)  # keyed by the stored session: a participant's next step computes only their task again
def session_consistency(state_json: str) -> dict[str, Any]:
    """One teaching session's verdict probabilities (per learning step, then per test), score, lowest and flag."""
    learning, tests = session_verdict_probabilities(session_of(state_json))
    verdicts = [p for p in learning if p is not None] + tests
    lowest = min(verdicts) if verdicts else None
    return {"p_verdicts": [None, *learning], "p_tests": tests, "n_verdicts": len(verdicts),
            "score": consistency_score(verdicts), "lowest": lowest,
            "flagged": flagged(verdicts)}


def participant_consistency(sessions: Iterable[tuple[int, str]]) -> dict[str, Any]:
    """A participant's consistency over their tasks ((task index, stored session) pairs): each task's score and
    flag, the lowest task score, and whether any task is flagged."""
    tasks = []
    for task_index, state_json in sessions:
        view = session_consistency(state_json)
        tasks.append({"task_index": task_index, "score": view["score"], "lowest": view["lowest"],
                      "n_verdicts": view["n_verdicts"], "flagged": view["flagged"]})
    scores = [t["score"] for t in tasks if t["score"] is not None]
    return {"score": min(scores) if scores else None, "flagged": any(t["flagged"] for t in tasks),
            "flag_below": FLAG_BELOW, "tasks": tasks}
