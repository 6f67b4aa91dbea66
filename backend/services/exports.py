"""Per-study CSV exports: participants, events, steps, beliefs and questionnaire answers (pilots left out unless
asked for; erased participants never); the codebook that describes them is in codebook.py."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from ..core import session as core
from ..db import repository as repo
from ..db.tables import ParticipantRow, StudyRow
from ..errors import NotFound
from .consistency import session_consistency
from .context import Context, aware, iso
from .attention import SIGNALS
from .instruments import scores
from .monitoring import belief_view
from .outcomes import outcome_of
from .planning import session_of
from .state import task_sequence
from .studies import study_row

EXPORTS = ("participants", "events", "steps", "beliefs", "questionnaire", "scores")


PARTICIPANT_COLUMNS = [
    "participant_id", "study_id", "condition", "task_order", "pilot", "stage", "end_reason", "timed_out",
    "quiz_failures", "attention_failed", "task_index", "prolific_pid", "external_study_id",
    "external_session_id", "consent_at", "consent_version", "completion_code", "outcome", "created_at",
    "last_activity_at", "finished_at", "total_seconds", "n_events", "seed",
    "elapsed_seconds",
    "tab_hidden", "window_blur", "paste",
]


STEP_COLUMNS = [
    "participant_id", "condition", "task_position", "task_index", "task", "step_kind", "step_index", "shown_at",
    "answered_at", "duration_seconds", "n_objects", "acceptable",
    "learning_step",  # the belief step (beliefs.csv "step") this step's answer led to
    "shown_fraction", "replays_watched",
]


EVENT_COLUMNS = [
    "participant_id", "seq", "created_at", "kind", "task_index", "task", "step_kind", "step_index", "object",
    "labels", "robot_events", "trace", "acceptable", "p_acceptable", "client_event_id", "app_version", "payload",
]


BELIEF_COLUMNS = [
    "participant_id", "condition", "task_index", "task", "step", "record_kind", "acceptable", "trace", "entropy",
    "map_formula", "map_description", "similarity", "map_similarity",
] + [f"top{i}_{part}" for i in range(1, 6) for part in ("formula", "p")] + [
    "p_verdict", "consistency_score", "consistency_flag",  # teacher consistency (services.consistency)
    "step_kind", "step_index",  # the step (steps.csv) whose answer this belief follows; empty for the prior
]


QUESTIONNAIRE_COLUMNS = ["participant_id", "condition", "item_id", "item_kind", "item_text", "answer",
                         "attention_check", "attention_expected", "attention_passed", "answered_at"]


# What participants.csv keeps of a withdrawn participant (their events, answers and beliefs are deleted).
WITHDRAWN_KEEPS = frozenset({"participant_id", "study_id", "pilot", "stage", "end_reason", "timed_out",
                             "completion_code", "outcome", "finished_at", "n_events"})

SCORE_COLUMNS = ["participant_id", "condition", "instrument", "scale", "score", "n_items", "answered_at"]


EXPORT_COLUMNS = {"participants": PARTICIPANT_COLUMNS, "events": EVENT_COLUMNS, "steps": STEP_COLUMNS,
                  "beliefs": BELIEF_COLUMNS, "questionnaire": QUESTIONNAIRE_COLUMNS, "scores": SCORE_COLUMNS}


# The event that answers each kind of step: its time minus the time the step was shown is the step's duration.
ANSWERS = {"demonstration": ("practice", "demonstration"), "assessment": ("query", "test")}


# The steps whose answers the learner learns from (core.session: SessionState.learning_records).
LEARNING_KINDS = ("demonstration", "query")


def _json(value: Any) -> str | None:
    return None if value is None else json.dumps(value, separators=(",", ":"))


def export_rows(ctx: Context, study_id: str, name: str, *, include_pilot: bool = False) -> Iterator[list[Any]]:
    """The rows of one export, header first; checks the study (and screens out the timed-out) before the first
    row is produced."""
    if name not in EXPORTS:
        raise NotFound(f"no export named {name!r}; expected one of {', '.join(EXPORTS)}")
    with ctx.db.read() as s:
        study_row(s, study_id)
    return _export_rows(ctx, study_id, name, include_pilot)


def _seconds(start: Any, end: Any) -> float | None:
    start, end = aware(start), aware(end)
    return None if start is None or end is None else round((end - start).total_seconds(), 3)


def _export_rows(ctx: Context, study_id: str, name: str, include_pilot: bool) -> Iterator[list[Any]]:
    yield EXPORT_COLUMNS[name]
    if name == "beliefs":
        yield from _belief_rows(ctx, study_id, include_pilot)
        return
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        if name == "participants":
            stored = repo.count_study_events(s, study_id=study_id)
            for p in repo.list_participants(s, study_id=study_id, include_pilot=include_pilot):
                yield _participant_row(study, p, stored.get(p.id, 0))
        elif name == "steps":
            yield from _step_rows(s, study, include_pilot)
        elif name == "events":
            for e in repo.iter_study_events(s, study_id=study_id, include_pilot=include_pilot):
                pl = e.payload or {}
                task = None if e.task_index is None else study.tasks[e.task_index]["key"]
                yield [e.participant_id, e.seq, iso(e.created_at), e.kind, e.task_index, task, e.step_kind,
                       e.step_index, pl.get("object"), _json(pl.get("labels")), _json(pl.get("events")),
                       _json(pl.get("trace")), pl.get("acceptable"), pl.get("p_acceptable"), e.client_event_id,
                       e.app_version, _json(pl)]
        elif name == "scores":
            conditions = {p.id: p.condition for p in repo.list_participants(s, study_id=study_id)}
            for e in repo.iter_study_events(s, study_id=study_id, kind="questionnaire", include_pilot=include_pilot):
                for instrument, scale, score, n in scores(study.questionnaire, e.payload.get("answers") or {}):
                    yield [e.participant_id, conditions.get(e.participant_id), instrument, scale, score, n,
                           iso(e.created_at)]
        else:
            items = {item["id"]: item for item in study.questionnaire}
            conditions = {p.id: p.condition for p in repo.list_participants(s, study_id=study_id)}
            for e in repo.iter_study_events(s, study_id=study_id, kind="questionnaire", include_pilot=include_pilot):
                for item_id, answer in (e.payload.get("answers") or {}).items():
                    item = items.get(item_id, {})
                    check = item.get("kind") == "attention"
                    yield [e.participant_id, conditions.get(e.participant_id), item_id, item.get("kind"),
                           item.get("text"), answer, check, item.get("expected") if check else None,
                           answer == item.get("expected") if check else None, iso(e.created_at)]


def _participant_row(study: StudyRow, p: ParticipantRow, n_events: int) -> list[Any]:
    """One participants.csv row; a withdrawn participant's keeps only the fact of the withdrawal (as the consent
    text promises): number, study, pilot flag, stage, reason, the code shown and when."""
    row = [p.id, p.study_id, p.condition, _json(p.task_order or list(range(len(study.tasks)))), p.pilot,
           p.stage, p.end_reason, p.end_reason == "timeout", p.quiz_failures, p.attention_failed,
           p.task_index, p.prolific_pid, p.external_study_id, p.external_session_id, iso(p.consent_at),
           p.consent_version, p.completion_code, outcome_of(p), iso(p.created_at), iso(p.last_activity_at),
           iso(p.finished_at), _seconds(p.created_at, p.finished_at), n_events, p.seed,
           _seconds(p.created_at, p.finished_at or p.last_activity_at),
           *((p.attention_signals or {}).get(k, 0) for k in SIGNALS)]
    if p.end_reason == "withdrew":
        kept = WITHDRAWN_KEEPS
        row = [value if column in kept else None for column, value in zip(PARTICIPANT_COLUMNS, row, strict=True)]
    return row


def _step_rows(s: Any, study: StudyRow, include_pilot: bool) -> Iterator[list[Any]]:
    """One row per answered step: when it was shown (its task started or the previous step was answered), when
    it was answered, and the seconds between."""
    participants = {p.id: p for p in repo.list_participants(s, study_id=study.id)}
    shown: dict[tuple[int, int], Any] = {}
    learned: dict[tuple[int, int], int] = {}
    for e in repo.iter_study_events(s, study_id=study.id, include_pilot=include_pilot):
        if e.task_index is None:
            continue
        key = (e.participant_id, e.task_index)
        if e.kind == "task_started":
            shown[key] = e.created_at
        elif e.step_kind in ANSWERS.get(e.kind, ()):
            p = participants.get(e.participant_id)
            if p is None:
                continue
            pl = e.payload or {}
            objects = pl.get("placed") if e.kind == "demonstration" else pl.get("events")
            learning_step = None
            if e.step_kind in LEARNING_KINDS:  # the belief after this answer is beliefs.csv's next step
                learned[key] = learning_step = learned.get(key, 0) + 1
            # As the learner takes it: a demonstration is acceptable; a query or test has the participant's verdict.
            acceptable = pl.get("acceptable") if e.kind == "assessment" else True
            yield [p.id, p.condition, task_sequence(study, p).index(e.task_index), e.task_index,
                   study.tasks[e.task_index]["key"], e.step_kind, e.step_index, iso(shown.get(key)),
                   iso(e.created_at), _seconds(shown.get(key), e.created_at), len(objects or []),
                   acceptable, learning_step,
                   pl.get("shown_fraction") if e.kind == "assessment" else None,
                   pl.get("replays") if e.kind == "assessment" else None]
            shown[key] = e.created_at


def _belief_rows(ctx: Context, study_id: str, include_pilot: bool) -> Iterator[list[Any]]:
    """beliefs.csv's rows, computed after the read transaction (past five objects each belief takes seconds)."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        tasks_def = list(study.tasks)
        conditions = {p.id: p.condition for p in repo.list_participants(s, study_id=study.id)}
        stored = [(ts.participant_id, ts.task_index, ts.state_json)
                  for ts in repo.iter_study_task_sessions(s, study_id=study.id, include_pilot=include_pilot)]
    for participant_id, task_index, state_json in stored:
        state = session_of(state_json)
        task = tasks_def[task_index]
        data = core.learning_verdicts(state)
        records: list[core.Record | None] = [None, *state.learning_records]
        consistency = session_consistency(state_json)  # teacher consistency (services.consistency)
        p_verdicts, score, flagged = consistency["p_verdicts"], consistency["score"], consistency["flagged"]
        seen: dict[str, int] = {}
        for step, record in enumerate(records):
            kind_index = None
            if record is not None:
                kind_index = seen.get(record.kind, 0)
                seen[record.kind] = kind_index + 1
            view = belief_view(state.config.task, state.config.prior, data[:step], task.get("ground_truth"), 5,
                               state.config.flip_rate)
            cells: list[Any] = []
            for i in range(5):
                cells += ([view["top"][i]["formula"], view["top"][i]["p"]] if i < len(view["top"])
                          else [None, None])
            yield [participant_id, conditions.get(participant_id), task_index, task["key"], step,
                   None if record is None else record.kind, None if record is None else record.acceptable,
                   None if record is None else _json([sorted(x) for x in record.trace]),
                   view["entropy"], view["map_formula"], view["map_description"], view["similarity"],
                   view["map_similarity"], *cells, p_verdicts[step], score, flagged,
                   None if record is None else record.kind, kind_index]
