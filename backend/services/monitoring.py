"""What experimenters see live: participants' status and per-participant belief summaries."""

from __future__ import annotations

from datetime import datetime
from functools import lru_cache
from typing import Any

from ..config import Settings
from ..core import learner_seam as seam
from ..core import session as core
from ..core.domain import get_domain
from ..db import repository as repo
from ..db.tables import ParticipantRow, utcnow
from ..errors import NotFound
from .context import Context, aware, iso
from .outcomes import outcome_of
from .planning import session_of
from .studies import study_row

FINISHED = ("done", "withdrawn", "screened_out")
MARGINALS = 10  # clause marginals shown with a belief (the MAP's company past five objects, where no list exists)


def inactive_minutes(participant: ParticipantRow, now: datetime) -> float:
    """Minutes since the participant's last request (0 if none is recorded)."""
    last = aware(participant.last_activity_at) or now
    return max(0.0, (now - last).total_seconds() / 60)


def live_status(participant: ParticipantRow, settings: Settings, now: datetime) -> str:
    """done / withdrawn / screened_out, else active or idle by the settings' active_minutes."""
    if participant.stage in FINISHED:
        return participant.stage
    return "active" if inactive_minutes(participant, now) <= settings.active_minutes else "idle"


def participant_row(participant: ParticipantRow, settings: Settings, now: datetime) -> dict[str, Any]:
    """The fields every experimenter view shows about a participant."""
    p = participant
    return {
        "participant_id": p.id, "condition": p.condition, "stage": p.stage, "task_index": p.task_index,
        "status": live_status(p, settings, now), "pilot": p.pilot, "prolific_pid": p.prolific_pid,
        "created_at": iso(p.created_at), "last_activity_at": iso(p.last_activity_at),
        "finished_at": iso(p.finished_at), "n_events": p.n_events, "completion_code": p.completion_code,
        "outcome": outcome_of(p), "end_reason": p.end_reason, "attention_failed": p.attention_failed,
        "task_order": p.task_order,
        "elapsed_seconds": _elapsed(p, now), "attention_signals": dict(p.attention_signals or {}),
    }


def _elapsed(participant: ParticipantRow, now: datetime) -> float | None:
    """Seconds from joining to finishing (or to now while under way)."""
    start = aware(participant.created_at)
    end = aware(participant.finished_at) or now
    return None if start is None else round(max(0.0, (end - start).total_seconds()), 1)


def study_participant(s: Any, study_id: str, participant_id: int) -> ParticipantRow:
    """A participant of a study; NotFound names both otherwise."""
    participant = repo.get_participant(s, study_id=study_id, participant_id=participant_id)
    if participant is None:
        raise NotFound(f"study {study_id!r} has no participant {participant_id}")
    return participant


def list_participants(ctx: Context, study_id: str) -> list[dict[str, Any]]:
    """A study's participants with their stage, current phase, live status and last activity."""
    with ctx.db.read() as s:
        study_row(s, study_id)
    now = utcnow()
    with ctx.db.read() as s:
        study_row(s, study_id)
        current = repo.current_task_sessions(s, study_id=study_id)
        out = []
        for p in repo.list_participants(s, study_id=study_id):
            ts = current.get(p.id)
            phase = None if ts is None else session_of(ts.state_json).phase
            out.append({**participant_row(p, ctx.settings, now), "phase": phase})
        return out


@lru_cache(maxsize=65536)  # the same few formulas head most participants' beliefs
def _formula_view(task: str, mask: int) -> tuple[str, str]:
    """A clause set's formula text and plain-English description."""
    space = get_domain(task).clause_space
    return space.text_of(mask), space.describe(mask)


# Keyed by the data so far, not by the whole session: when a participant adds a step, the dashboard's
# next poll computes that one step, not all of them again. Callers must not change what it returns.
@lru_cache(maxsize=16384)
def belief_view(task: str, prior: str, data: core.Verdicts, truth_formula: str | None, top: int,
                flip_rate: float = 0.0) -> dict[str, Any]:
    """Entropy, similarity to the truth, MAP and top formulas of the belief after these (trace, acceptable,
    is_verdict) items, for the learner with this flip rate (0: the authors'), asked through the learner seam:
    past five objects ``top`` holds the MAP formula alone with its probability (the exact learner lists no
    formulas; ``marginals_view`` gives the clauses most probably in the formula)."""
    belief = seam.belief_after(task, prior, flip_rate, data)
    truth = None if truth_formula is None else get_domain(task).clause_space.mask_of_formula(truth_formula)
    map_formula, map_description = _formula_view(task, belief.map_mask)
    top_formulas = []
    for mask, p in belief.top(top):
        formula, description = _formula_view(task, mask)
        top_formulas.append({"formula": formula, "description": description, "p": p})
    return {
        "entropy": belief.entropy,
        "similarity": None if truth is None else belief.similarity(truth),
        "map_similarity": None if truth is None else belief.map_similarity(truth),
        "map_formula": map_formula,
        "map_description": map_description,
        "top": top_formulas,
        "learner": belief.path,
        "map_p": belief.map_probability,
    }


@lru_cache(maxsize=16384)
def marginals_view(task: str, prior: str, data: core.Verdicts, flip_rate: float = 0.0,
                   k: int = MARGINALS) -> list[dict[str, Any]]:
    """The k clauses most probably in the formula after these items, with their probabilities (either learner;
    the dashboard's company for the MAP past five objects). Callers must not change what it returns."""
    return seam.clause_texts(seam.belief_after(task, prior, flip_rate, data).top_marginals(k))


def belief_summary(ctx: Context, study_id: str, participant_id: int, *, top: int = 5) -> dict[str, Any]:
    """Per task: the learner's top formulas in plain English (past five objects the MAP formula and the clause
    marginals), entropy and similarity to the ground truth."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        participant = study_participant(s, study_id, participant_id)
        stored = [(ts.task_index, ts.state_json) for ts in repo.task_sessions_of(s, participant_id=participant.id)]
        tasks_def = list(study.tasks)
        who = {"participant_id": participant.id, "condition": participant.condition, "stage": participant.stage}
    tasks = []  # outside the transaction: past five objects a belief takes seconds
    for task_index, state_json in stored:
        state = session_of(state_json)
        task = tasks_def[task_index]
        data = core.learning_verdicts(state)
        view = belief_view(state.config.task, state.config.prior, data, task.get("ground_truth"), top,
                           state.config.flip_rate)
        marginals = marginals_view(state.config.task, state.config.prior, data, state.config.flip_rate)
        tasks.append({"task_index": task_index, "task": task["key"], "phase": state.phase,
                      "n_observations": len(state.learning_records), **view,
                      "marginals": [dict(m) for m in marginals]})
    return {**who, "tasks": tasks}
