"""What experimenters see live: participants' status and per-participant belief summaries."""

from __future__ import annotations

from datetime import datetime
from functools import lru_cache
from typing import Any

from ..config import Settings
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
    is_verdict) items, for the learner with this flip rate (0: the authors')."""
    belief = core.noisy_belief_after(task, prior, flip_rate, data)
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
    }


def belief_summary(ctx: Context, study_id: str, participant_id: int, *, top: int = 5) -> dict[str, Any]:
    """Per task: the learner's top formulas in plain English, entropy and similarity to the ground truth."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        participant = study_participant(s, study_id, participant_id)
        tasks = []
        for ts in repo.task_sessions_of(s, participant_id=participant.id):
            state = session_of(ts.state_json)
            task = study.tasks[ts.task_index]
            view = belief_view(state.config.task, state.config.prior, core.learning_verdicts(state),
                               task.get("ground_truth"), top, state.config.flip_rate)
            tasks.append({"task_index": ts.task_index, "task": task["key"], "phase": state.phase,
                          "n_observations": len(state.learning_records), **view})
        return {"participant_id": participant.id, "condition": participant.condition, "stage": participant.stage,
                "tasks": tasks}
