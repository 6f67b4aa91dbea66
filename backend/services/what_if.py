"""What if: one participant's recorded demonstrations and verdicts replayed through other learner configurations,
step by step, beside the study's own learner (the dashboard's view of ``tableteach replay``; core.counterfactual).

Read only; every belief is rebuilt from the stored sessions, so nothing the participant saw changes.
"""

from __future__ import annotations

from typing import Any, Sequence

from ..core import session as core
from ..core.counterfactual import LearnerSpec, parse_learners, step_views
from ..core.domain import get_domain
from ..db import repository as repo
from ..errors import InvalidInput
from .context import Context
from .monitoring import study_participant
from .planning import session_of
from .studies import study_row

MAX_LEARNERS = 6  # each one rebuilds every step's belief of every task
DEFAULT_LEARNERS = ("flip=0.1", "data=demonstrations")


def learners_of(texts: Sequence[str]) -> list[LearnerSpec]:
    """The study's own learner first, then the asked-for ones (each once); InvalidInput names a bad one."""
    texts = [t for t in texts if t.strip() != "study"] or list(DEFAULT_LEARNERS)
    if len(texts) > MAX_LEARNERS:
        raise InvalidInput(f"learner: at most {MAX_LEARNERS} learners at once, got {len(texts)}")
    try:
        return parse_learners(["study", *texts])
    except ValueError as exc:
        raise InvalidInput(f"learner: {exc}") from None


def _learner_view(learner: LearnerSpec, study_prior: str, study_flip_rate: float) -> dict[str, Any]:
    prior, flip_rate = learner.resolved(study_prior, study_flip_rate)
    return {"learner": learner.name, "prior": prior, "flip_rate": flip_rate, "data": learner.data}


def _learner_steps(spec: LearnerSpec, data: core.Verdicts, truth: int | None, task: str, prior: str,
                   flip: float) -> dict[str, Any]:
    """One learner's steps, or why it cannot run on this task (past five objects the exact learner has no
    noise-aware likelihood and no forest prior yet): then its steps are empty and ``unavailable`` says why."""
    try:
        steps = step_views(spec, data, truth, task=task, study_prior=prior, study_flip_rate=flip)
    except ValueError as exc:
        return {**_learner_view(spec, prior, flip), "steps": [], "unavailable": str(exc)}
    return {**_learner_view(spec, prior, flip), "steps": steps, "unavailable": None}


def what_if(ctx: Context, study_id: str, participant_id: int, learners: Sequence[str] = ()) -> dict[str, Any]:
    """Per task the participant started: each learner's similarity, entropy and MAP formula after every step."""
    specs = learners_of(learners)
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        participant = study_participant(s, study_id, participant_id)
        stored = [(ts.task_index, ts.state_json) for ts in repo.task_sessions_of(s, participant_id=participant.id)]
        tasks_def, study_prior, study_flip = list(study.tasks), study.prior, float(study.flip_rate or 0.0)
    tasks = []
    for task_index, state_json in stored:
        state = session_of(state_json)
        space = get_domain(state.config.task).clause_space
        task = tasks_def[task_index]
        truth_text = task.get("ground_truth")
        truth = None if truth_text is None else space.mask_of_formula(truth_text)
        data = core.learning_verdicts(state)
        # the session's own settings are the study's (a study's learner settings are fixed once it opens)
        prior, flip = state.config.prior, state.config.flip_rate
        tasks.append({
            "task_index": task_index, "task": task["key"], "name": task.get("name"),
            "has_ground_truth": truth is not None,
            "records": [None, *(r.kind for r in state.learning_records)],
            "learners": [_learner_steps(spec, data, truth, state.config.task, prior, flip) for spec in specs],
        })
    return {"study_id": study_id, "participant_id": participant_id, "study_prior": study_prior,
            "study_flip_rate": study_flip, "tasks": tasks}
