"""The experimenter's analysis views: live participant table, one participant's history, learning curves, replays.

Read-only: every function opens a read transaction, rebuilds beliefs with the learning core (the study's
own learner, through core.learner_seam) and never writes. The learning curves follow the paper's user-study
figure: the median expected similarity to the ground truth E_P[L(phi, phi*)] and the mean entropy of
the belief after each learning step (step 0 is the prior, step k the belief after the k-th
demonstration or assessed query).
"""

from __future__ import annotations

import statistics
from typing import Any

from ..core import learner_seam as seam
from ..core import session as core
from ..core.domain import get_domain
from ..db import analysis_queries as aq
from ..db import repository as repo
from ..db.tables import EventRow, utcnow
from ..errors import NotFound
from ..recording_store import RecordingId
from .consistency import FLAG_BELOW, participant_consistency, session_consistency
from .context import Context, iso
from .monitoring import (
    belief_view,
    FINISHED,
    marginals_view,
    inactive_minutes,
    participant_row,
    study_participant,
)
from .planning import session_of
from .studies import study_row
from .study_objects import study_domain, study_scene

TOP_K = 5


# ====================================================================== live table


def _step_of(state: core.SessionState) -> dict[str, Any]:
    """Where a teaching session is (without planning the robot's next execution)."""
    kind, index, total = core.position(state)
    return {"kind": kind, "index": index, "total": total}


def live_participants(ctx: Context, study_id: str, *, dropout_minutes: float | None = None) -> dict[str, Any]:
    """Participants with their current step and inactivity; unfinished ones idle past the threshold are dropouts."""
    threshold = ctx.settings.active_minutes if dropout_minutes is None else dropout_minutes
    now = utcnow()
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        current = repo.current_task_sessions(s, study_id=study_id)
        stored: dict[int, list[tuple[int, str]]] = {}
        for session in repo.iter_study_task_sessions(s, study_id=study_id):
            stored.setdefault(session.participant_id, []).append((session.task_index, session.state_json))
        rows = []
        for p in repo.list_participants(s, study_id=study_id):
            inactive = inactive_minutes(p, now)
            ts = current.get(p.id)
            step = None if ts is None else {"task_index": p.task_index, **_step_of(session_of(ts.state_json))}
            rows.append({
                **participant_row(p, ctx.settings, now), "n_tasks": len(study.tasks), "step": step,
                "dropout": p.stage not in FINISHED and inactive > threshold, "inactive_minutes": inactive,
                "consistency": participant_consistency(stored.get(p.id, [])),
            })
    return {"study_id": study_id, "now": now.isoformat(), "dropout_minutes": threshold, "participants": rows}


# ====================================================================== beliefs per step


def _step_summaries(state_json: str, truth_formula: str | None, top: int) -> list[dict[str, Any]]:
    """The belief after each learning step of a stored session: entropy, similarity, MAP and top formulas."""
    state = session_of(state_json)
    task, prior, flip_rate = state.config.task, state.config.prior, state.config.flip_rate
    data = core.learning_verdicts(state)
    records: list[core.Record | None] = [None, *state.learning_records]
    return [
        {"step": step, "record": None if record is None else {
            "kind": record.kind, "acceptable": record.acceptable, "trace": [sorted(x) for x in record.trace]},
         **belief_view(task, prior, data[:step], truth_formula, top, flip_rate),
         "marginals": marginals_view(task, prior, data[:step], flip_rate)}
        for step, record in enumerate(records)
    ]


def _curve_of(state_json: str, truth_formula: str | None) -> tuple[list[float], list[float | None]]:
    """Entropy and expected similarity after each learning step (what the curves need: no MAP, which past five
    objects costs more than both)."""
    state = session_of(state_json)
    c = state.config
    data = core.learning_verdicts(state)
    truth = None if truth_formula is None else get_domain(c.task).clause_space.mask_of_formula(truth_formula)
    beliefs = [seam.belief_after(c.task, c.prior, c.flip_rate, data[:step]) for step in range(len(data) + 1)]
    return ([b.entropy for b in beliefs], [None if truth is None else b.similarity(truth) for b in beliefs])


def _task_steps(state_json: str, truth: str | None) -> list[dict[str, Any]]:
    """Fresh copies of the cached summaries (callers may change them)."""
    return [{**step, "top": [dict(t) for t in step["top"]], "marginals": [dict(m) for m in step["marginals"]]}
            for step in _step_summaries(state_json, truth, TOP_K)]


# ====================================================================== one participant's history


def _executions(events: list[EventRow]) -> list[dict[str, Any]]:
    """Every practice trial, demonstration, query and test in order, with trace, verdict and learning step."""
    out: list[dict[str, Any]] = []
    by_step: dict[tuple[int | None, str | None, int | None], dict[str, Any]] = {}
    learned: dict[int | None, int] = {}
    for e in events:
        pl = e.payload or {}
        if e.kind not in ("place", "demonstration", "execution_started", "execution_finished", "assessment"):
            continue
        key = (e.task_index, e.step_kind, e.step_index)
        item = by_step.get(key)
        if item is None:
            item = {"task_index": e.task_index, "kind": e.step_kind, "index": e.step_index,
                    "by": "participant" if e.kind in ("place", "demonstration") else "robot", "status": "running",
                    "objects": None, "trace": None, "acceptable": None, "p_acceptable": None,
                    "learning_step": None, "started_at": iso(e.created_at), "finished_at": None}
            by_step[key] = item
            out.append(item)
        if e.kind == "place":
            item.update(objects=pl.get("placed"))
        elif e.kind == "demonstration":
            item.update(status="finished", objects=pl.get("placed"), trace=pl.get("trace"),
                        acceptable=True if e.step_kind == "demonstration" else None, finished_at=iso(e.created_at))
        elif e.kind == "execution_started":
            item.update(objects=pl.get("events"), p_acceptable=pl.get("p_acceptable"))
        elif e.kind == "execution_finished":
            item.update(status="finished", objects=pl.get("events"), trace=pl.get("trace"),
                        finished_at=iso(e.created_at))
        else:
            item.update(status="assessed", objects=pl.get("events"), trace=pl.get("trace"),
                        acceptable=pl.get("acceptable"), p_acceptable=pl.get("p_acceptable", item["p_acceptable"]))
        # The learner's data are demonstrations and assessed queries, in the order they were stored.
        if (e.kind, e.step_kind) in (("demonstration", "demonstration"), ("assessment", "query")):
            learned[e.task_index] = learned.get(e.task_index, 0) + 1
            item["learning_step"] = learned[e.task_index]
    return out


def _event_view(e: EventRow) -> dict[str, Any]:
    return {"seq": e.seq, "created_at": iso(e.created_at), "kind": e.kind, "task_index": e.task_index,
            "step_kind": e.step_kind, "step_index": e.step_index, "payload": e.payload or {}}


def participant_history(ctx: Context, study_id: str, participant_id: int) -> dict[str, Any]:
    """Everything one participant did: events, executions with traces and verdicts, the belief after each step."""
    now = utcnow()
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        space = study_domain(study).clause_space
        p = study_participant(s, study_id, participant_id)
        events = aq.participant_events(s, participant_id=p.id)
        executions = _executions(events)
        tasks = []
        for ts in repo.task_sessions_of(s, participant_id=p.id):
            task = study.tasks[ts.task_index]
            truth = task.get("ground_truth")
            state = core.SessionState.from_json(ts.state_json)
            tasks.append({
                "task_index": ts.task_index, "task": task["key"], "name": task.get("name"),
                "ground_truth": truth,
                "ground_truth_description": None if truth is None else space.describe(space.mask_of_formula(truth)),
                "step": _step_of(state), "steps": ts.state_json,  # the beliefs: below, outside the transaction
                "executions": [x for x in executions if x["task_index"] == ts.task_index],
            })
        items = {item["id"]: item for item in study.questionnaire}
        answers = [
            {"item_id": item_id, "text": items.get(item_id, {}).get("text"), "kind": items.get(item_id, {}).get("kind"),
             "answer": answer}
            for e in events if e.kind == "questionnaire"
            for item_id, answer in (e.payload.get("answers") or {}).items()
        ]
        out = {
            "study_id": study_id,
            "participant": {**participant_row(p, ctx.settings, now), "seed": p.seed},
            "tasks": tasks,
            "events": [_event_view(e) for e in events],
            "questionnaire": answers,
        }
    for task in tasks:  # past five objects each step's belief takes seconds: no transaction waits for them
        state_json = task["steps"]
        task["steps"] = _task_steps(state_json, task["ground_truth"])
        task["consistency"] = _consistency_view(state_json)
    return out


def _consistency_view(state_json: str) -> dict[str, Any]:
    """A task's teacher consistency as the history shows it (services.consistency)."""
    view = session_consistency(state_json)
    return {**{k: view[k] for k in ("p_verdicts", "p_tests", "n_verdicts", "score", "lowest", "flagged")},
            "flag_below": FLAG_BELOW}


# ====================================================================== learning curves


def _curve_points(series: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per learning step: how many participants reached it, median similarity (with its count) and mean entropy."""
    longest = max((len(x["entropy"]) for x in series), default=0)
    points = []
    for step in range(longest):
        entropies = [x["entropy"][step] for x in series if step < len(x["entropy"])]
        sims = [x["similarity"][step] for x in series
                if step < len(x["similarity"]) and x["similarity"][step] is not None]
        points.append({
            "step": step, "n": len(entropies), "mean_entropy": statistics.fmean(entropies),
            "n_similarity": len(sims), "median_similarity": statistics.median(sims) if sims else None,
            "q1_similarity": _quantile(sims, 0.25), "q3_similarity": _quantile(sims, 0.75),
        })
    return points


def _quantile(values: list[float], q: float) -> float | None:
    """Linear-interpolation quantile (numpy's default), None for no values."""
    if not values:
        return None
    ordered = sorted(values)
    pos = q * (len(ordered) - 1)
    low = int(pos)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (pos - low)


def learning_curves(ctx: Context, study_id: str, *, finished_only: bool = False,
                    include_pilot: bool = False) -> dict[str, Any]:
    """Per task and condition (and all conditions together): the curves across participants (pilots only if
    include_pilot), and each one's own."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        study_tasks, study_conditions = list(study.tasks), list(study.conditions)
        stored = [(ts.task_index, ts.state_json, p.id, p.condition, p.stage == "done")
                  for ts, p in aq.study_task_sessions_with_participants(s, study_id=study_id,
                                                                        include_pilot=include_pilot)
                  if not finished_only or p.stage == "done"]
    per_task: dict[int, list[dict[str, Any]]] = {i: [] for i in range(len(study_tasks))}
    for task_index, state_json, pid, condition, finished in stored:  # outside the transaction: beliefs take time
        entropy, similarity = _curve_of(state_json, study_tasks[task_index].get("ground_truth"))
        per_task[task_index].append({"participant_id": pid, "condition": condition, "finished": finished,
                                     "entropy": entropy, "similarity": similarity})
    tasks = []
    for index, series in per_task.items():
        task = study_tasks[index]
        conditions = [c for c in study_conditions if any(x["condition"] == c for x in series)]
        tasks.append({
            "task_index": index, "task": task["key"], "name": task.get("name"),
            "has_ground_truth": task.get("ground_truth") is not None,
            "all": _curve_points(series),
            "conditions": [{"condition": c, "points": _curve_points([x for x in series if x["condition"] == c])}
                           for c in conditions],
            "participants": series,
        })
    return {"study_id": study_id, "finished_only": finished_only, "include_pilot": include_pilot, "tasks": tasks}


# ====================================================================== replays


def replay(ctx: Context, study_id: str, participant_id: int, *, task_index: int, step_kind: str,
           step_index: int) -> dict[str, Any]:
    """One step's replay: the recorded poses if the robot saved them, else the trace to replay step by step."""
    with ctx.db.read() as s:
        scene = study_scene(study_row(s, study_id))
        participant = study_participant(s, study_id, participant_id)
        pid, uid = participant.id, participant.uid
        executions = _executions(aq.participant_events(s, participant_id=pid))
    found = [x for x in executions if (x["task_index"], x["kind"], x["index"]) == (task_index, step_kind, step_index)]
    if not found:
        raise NotFound(f"participant {participant_id} has no {step_kind} {step_index} in task {task_index} "
                       "(indices count from 0)")
    execution = found[0]
    if execution["trace"] is None:
        raise NotFound(f"{step_kind} {step_index} of task {task_index} has not finished yet; replay it when it has")
    layout = ctx.store.layout(scene)
    # The trace robot saves no recording: the dashboard replays the trace instead.
    recording = ctx.store.top_view(RecordingId(uid, task_index, step_kind, step_index), scene)
    return {"task_index": task_index, "kind": step_kind, "index": step_index,
            "source": "trace" if recording is None else "recording", "objects": execution["objects"] or [],
            "trace": execution["trace"], "acceptable": execution["acceptable"], "layout": layout,
            "recording": recording}
