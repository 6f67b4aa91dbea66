"""What experimenters see live: participants' status and per-participant belief summaries."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from ..config import Settings
from ..core import session as core
from ..core.domain import get_domain
from ..db import repository as repo
from ..db.tables import ParticipantRow, utcnow
from ..errors import NotFound
from .context import Context, aware, iso
from .state import current_task
from .studies import study_row


def _live_status(participant: ParticipantRow, settings: Settings) -> str:
    if participant.stage in ("done", "withdrawn"):
        return participant.stage
    last = aware(participant.last_activity_at) or utcnow()
    return "active" if utcnow() - last <= timedelta(minutes=settings.active_minutes) else "idle"


def list_participants(ctx: Context, study_id: str) -> list[dict[str, Any]]:
    """A study's participants with their stage, live status and last activity."""
    with ctx.db.read() as s:
        study_row(s, study_id)
        out = []
        for p in repo.list_participants(s, study_id=study_id):
            step = None
            ts = current_task(s, p)
            if ts is not None:
                nxt = core.SessionState.from_json(ts.state_json).phase
                step = nxt
            out.append({
                "participant_id": p.id, "condition": p.condition, "stage": p.stage, "task_index": p.task_index,
                "phase": step, "status": _live_status(p, ctx.settings), "pilot": p.pilot,
                "prolific_pid": p.prolific_pid, "created_at": iso(p.created_at),
                "last_activity_at": iso(p.last_activity_at), "finished_at": iso(p.finished_at),
                "n_events": p.n_events, "completion_code": p.completion_code,
            })
        return out


def truth_mask(task: dict[str, Any]) -> int | None:
    formula = task.get("ground_truth")
    return None if formula is None else get_domain("dinner").clause_space.mask_of_formula(formula)


def belief_summary(ctx: Context, study_id: str, participant_id: int, *, top: int = 5) -> dict[str, Any]:
    """Per task: the learner's top formulas in plain English, entropy and similarity to the ground truth."""
    space = get_domain("dinner").clause_space
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        participant = repo.get_participant(s, study_id=study_id, participant_id=participant_id)
        if participant is None:
            raise NotFound(f"study {study_id!r} has no participant {participant_id}")
        tasks = []
        for ts in repo.task_sessions_of(s, participant_id=participant.id):
            state = core.SessionState.from_json(ts.state_json)
            b = core.belief(state)
            truth = truth_mask(study.tasks[ts.task_index])
            tasks.append({
                "task_index": ts.task_index, "task": study.tasks[ts.task_index]["key"], "phase": state.phase,
                "n_observations": len(state.learning_records), "entropy": b.entropy,
                "map_formula": space.text_of(b.map_mask), "map_description": space.describe(b.map_mask),
                "similarity": None if truth is None else b.similarity(truth),
                "map_similarity": None if truth is None else b.map_similarity(truth),
                "top": [{"formula": space.text_of(m), "description": space.describe(m), "p": p} for m, p in b.top(top)],
            })
        return {"participant_id": participant.id, "condition": participant.condition, "stage": participant.stage,
                "tasks": tasks}
