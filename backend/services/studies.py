"""Studies: validation of their specification, create/open/close/list, and the demo study."""

from __future__ import annotations

import secrets
from typing import Any

from ..core.domain import DINNER_TASK_FORMULAS
from ..db import repository as repo
from ..db.tables import StudyRow, utcnow
from ..errors import Conflict, InvalidFields, NotFound
from .context import Context, commit, iso
from .outcomes import OUTCOME_CODE_FIELDS
from .study_definition import ProblemList, TaskIn, describe_formula, scene_spec, validate_study
from .instruments import INSTRUMENT_KINDS
from .page_settings import check_page_settings, page_settings_view

TASK_FORMULAS = DINNER_TASK_FORMULAS


TASK_NAMES = {"task1": "Task 1: set the table for dinner", "task2": "Task 2: a light meal"}


TASK_INSTRUCTIONS = {
    "task1": "Place all five objects. The dinner plate comes first of the three dishes, then the small plate, "
    "then the bowl; the knife and fork may be placed at any time.",
    "task2": "Place the dinner plate and then the bowl; never place the small plate. The knife and fork are "
    "optional. Finish the demonstration when you are done.",
}


TASK_KEYS = ("task1", "task2", "custom", "none")


ASSIGNMENTS = ("random", "balanced")


STUDY_STATUSES = ("draft", "open", "closed")


ITEM_KINDS = {"likert5": (1, 5), "rating10": (1, 10), "text": None, "attention": (1, 5),
              **{kind: (low, high) for kind, (low, high, _step) in INSTRUMENT_KINDS.items()}}


TASK_ORDERS = ("fixed", "random", "balanced")


CODE_FIELDS = (*OUTCOME_CODE_FIELDS.values(), "screened_out_code")


# What an experimenter may still change once participants can join (nothing they experience differently).
LIVE_FIELDS = ("name", "pilot", *CODE_FIELDS, "completion_url", "timeout_minutes", "places")


DEMO_STUDY_ID = "demo"




ROBOT_SPEEDS = (1.0, 3.0)  # a study shows the robot's motion 1x to 3x faster than recorded (recordings keep real time)


DEFAULT_CONSENT = (
    "You will teach a simulated robot to set a table by showing it and by judging its attempts. "
    "Your actions and answers are recorded without your name. You may stop at any time with the "
    "\"Withdraw\" link at the top of every page: your recorded actions and answers are then deleted, and we "
    "keep only the fact that you withdrew."
)


DEMO_QUESTIONNAIRE = [
    {"id": "learned", "text": "The robot learned the task I was teaching.", "kind": "likert5", "required": True},
    {"id": "queries_useful", "text": "The robot's questions helped it learn.", "kind": "likert5", "required": True},
    {"id": "easy", "text": "Teaching the robot was easy.", "kind": "likert5", "required": True},
    {"id": "trust", "text": "I would trust the robot to do this task on its own.", "kind": "likert5", "required": True},
    {"id": "again", "text": "I would like to teach a robot this way again.", "kind": "likert5", "required": True},
    {"id": "overall", "text": "Overall, how well did the robot learn? (1 = not at all, 10 = perfectly)",
     "kind": "rating10", "required": True},
    {"id": "comments", "text": "Anything else you want to tell us?", "kind": "text", "required": False},
]


def _task_values(tasks: list[TaskIn], objects: list[str] | None = None) -> list[dict[str, Any]]:
    """The tasks as stored: named tasks' fixed formulas, custom formulas in canonical form (over the study's own
    objects, if it has them), names and instructions."""
    out = []
    for i, task in enumerate(tasks):
        formula = TASK_FORMULAS.get(task.key) or task.ground_truth or None
        if task.key == "custom" and formula:
            formula = describe_formula(formula, objects)["formula"]
        out.append({
            "key": task.key,
            "ground_truth": formula,
            "name": task.name or TASK_NAMES.get(task.key, f"Task {i + 1}"),
            "instructions": task.instructions or TASK_INSTRUCTIONS.get(task.key)
            or ("" if formula is None else describe_formula(formula, objects)["description"]),
        })
    return out


def _study_values(spec: dict[str, Any]) -> dict[str, Any]:
    """Validated column values of a new study; InvalidFields lists every unacceptable field at once."""
    d = validate_study(spec)
    objects = None if not d.objects else scene_spec([o.model_dump() for o in d.objects]).to_json()
    return {
        "name": d.name or "Untitled study",
        "objects": objects,
        "tasks": _task_values(d.tasks, None if objects is None else [o["name"] for o in objects]),
        "conditions": list(d.conditions),
        "assignment": d.assignment,
        "n_practice": d.n_practice, "n_demonstrations": d.n_demonstrations, "n_queries": d.n_queries,
        "n_tests": d.n_tests,
        "prior": d.prior,
        "criterion": d.criterion,
        "questionnaire": [{"id": q.id, "text": q.text, "kind": q.kind,
                           "required": True if q.kind == "attention" else q.required,
                           **({"expected": q.expected} if q.kind == "attention" else {}),
                           **({"anchors": list(q.anchors)} if q.anchors else {}),
                           **({"instrument": q.instrument, "instrument_item": q.instrument_item}
                              if q.instrument else {})} for q in d.questionnaire],
        "consent_text": d.consent_text or DEFAULT_CONSENT,
        "consent_version": d.consent_version or "1",
        "completion_url": d.completion_url,
        "pilot": d.pilot,
        **{name: getattr(d, name) or None for name in CODE_FIELDS},
        "task_order": d.task_order,
        "quiz": [{"id": q.id, "text": q.text, "options": list(q.options), "correct": q.correct} for q in d.quiz],
        "quiz_max_attempts": d.quiz_max_attempts,
        "timeout_minutes": d.timeout_minutes,
        "robot_speed": float(d.robot_speed),
        "flip_rate": float(d.flip_rate),
        "places": d.places,
        **check_page_settings(spec, ProblemList()),  # checked by validate_study already
        "status": "draft",
    }


def study_problems(spec: dict[str, Any]) -> list[dict[str, str]]:
    """Every unacceptable field of a study specification (empty if it is acceptable)."""
    try:
        validate_study(spec)
    except InvalidFields as exc:
        return exc.errors
    return []


def study_view(study: StudyRow) -> dict[str, Any]:
    """A study as the experimenter API shows it."""
    return {
        "id": study.id, "name": study.name, "status": study.status, "pilot": study.pilot,
        "tasks": study.tasks, "conditions": study.conditions, "assignment": study.assignment,
        "n_practice": study.n_practice, "n_demonstrations": study.n_demonstrations,
        "n_queries": study.n_queries, "n_tests": study.n_tests, "prior": study.prior,
        "criterion": study.criterion, "questionnaire": study.questionnaire,
        "consent_text": study.consent_text, "consent_version": study.consent_version,
        "completion_url": study.completion_url, **{name: getattr(study, name) for name in CODE_FIELDS},
        "task_order": study.task_order, "quiz": study.quiz,
        "quiz_max_attempts": study.quiz_max_attempts, "timeout_minutes": study.timeout_minutes,
        "robot_speed": study.robot_speed, "flip_rate": float(study.flip_rate or 0.0),
        "places": study.places, "archived_at": iso(study.archived_at),
        **({"objects": study.objects} if study.objects else {}),  # the dinner table's studies read as before
        **page_settings_view(study),
        "created_at": iso(study.created_at), "updated_at": iso(study.updated_at),
    }


def create_study(ctx: Context, spec: dict[str, Any], *, study_id: str | None = None) -> dict[str, Any]:
    """Create a study in draft status."""
    values = _study_values(spec)
    with ctx.db.write() as s:
        sid = study_id or "s-" + secrets.token_urlsafe(6).replace("_", "x").replace("-", "x").lower()
        if repo.get_study(s, study_id=sid) is not None:
            raise Conflict(f"a study with id {sid!r} already exists")
        study = repo.add_study(s, values={"id": sid, **values})
        commit(s)
        return study_view(study)


def editable_spec(study: dict[str, Any]) -> dict[str, Any]:
    """A stored study (study_view) as the specification that would create it again."""
    spec = {k: v for k, v in study.items() if k not in ("id", "status", "created_at", "updated_at", "archived_at")
            and not (k == "objects" and v is None)}
    spec["tasks"] = [{k: v for k, v in t.items() if not (k == "ground_truth" and t["key"] in TASK_FORMULAS)}
                     for t in study["tasks"]]
    return spec


def update_study(ctx: Context, study_id: str, changes: dict[str, Any]) -> dict[str, Any]:
    """Edit a study: any field while it is a draft; once opened, only LIVE_FIELDS (the rest would differ
    between participants). Fields not named in changes keep their stored values."""
    with ctx.db.write() as s:
        study = study_row(s, study_id, for_update=True)
        current = study_view(study)
        values = _study_values({**editable_spec(current), **changes})  # a bad field is a 422 before any 409
        if study.status != "draft":
            frozen = sorted(k for k, v in changes.items() if k not in LIVE_FIELDS and v != current.get(k))
            if frozen:
                raise Conflict(f"study {study_id!r} is {study.status}: {', '.join(frozen)} can change only while it "
                               f"is a draft (clone it to make a draft copy); expected only {', '.join(LIVE_FIELDS)}")
        values.pop("status")
        if values["timeout_minutes"] != study.timeout_minutes:
            study.timeout_changed_at = utcnow()  # the new limit counts idleness from now on
        for name, value in values.items():
            if getattr(study, name) != value:
                setattr(study, name, value)
        commit(s)
        return study_view(study)


def clone_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """A draft copy of a study (any status) under a new id; the original is not changed."""
    original = get_study(ctx, study_id)
    spec = editable_spec(original)
    spec["name"] = f"Copy of {original['name']}"[:200]
    return create_study(ctx, spec)


def _set_study_status(ctx: Context, study_id: str, status: str) -> dict[str, Any]:
    allowed = {"open": ("draft", "closed", "open"), "closed": ("open", "draft", "closed")}[status]
    with ctx.db.write() as s:
        study = study_row(s, study_id)
        if study.status not in allowed:
            raise Conflict(f"study {study_id!r} is {study.status}; it cannot become {status}")
        study.status = status
        commit(s)
        return study_view(study)


def open_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """Let participants join."""
    return _set_study_status(ctx, study_id, "open")


def close_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """Stop new participants from joining (those under way may finish)."""
    return _set_study_status(ctx, study_id, "closed")


def list_studies(ctx: Context, *, include_archived: bool = False) -> list[dict[str, Any]]:
    """Every study (the archived ones only if asked for)."""
    with ctx.db.read() as s:
        return [study_view(st) for st in repo.list_studies(s) if include_archived or st.archived_at is None]


def archive_study(ctx: Context, study_id: str, *, archived: bool = True) -> dict[str, Any]:
    """Hide a study from the list (closing it if open), or bring it back; nothing of it is deleted."""
    with ctx.db.write() as s:
        study = study_row(s, study_id, for_update=True)
        if archived and study.status == "open":
            study.status = "closed"
        study.archived_at = utcnow() if archived else None
        commit(s)
        return study_view(study)


def delete_study(ctx: Context, study_id: str) -> None:
    """Delete a study that has no participants (Conflict otherwise: their data would be lost; archive it)."""
    with ctx.db.write() as s:
        study = study_row(s, study_id, for_update=True)
        kept = [p for p in repo.list_participants(s, study_id=study_id) if p.stage != "erased"]
        if kept:
            pilots = all(p.pilot for p in kept)
            raise Conflict(f"study {study_id!r} has {len(kept)} participant(s) whose data would be lost; "
                           + ("reset the pilot first, or archive it" if pilots else "archive it instead"))
        repo.delete_study(s, study=study)
        commit(s)


def get_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """One study."""
    with ctx.db.read() as s:
        return study_view(study_row(s, study_id))


def seed_demo_study(ctx: Context) -> dict[str, Any]:
    """The demo study (Task 1 then Task 2, Active protocol), created once and left open."""
    with ctx.db.read() as s:
        existing = repo.get_study(s, study_id=DEMO_STUDY_ID)
        if existing is not None:
            return study_view(existing)
    spec = {
        "name": "Demo: set the dinner table (Task 1 and Task 2, Active)",
        "tasks": [{"key": "task1"}, {"key": "task2"}],
        "conditions": ["active"],
        "questionnaire": DEMO_QUESTIONNAIRE,
        "pilot": True,
        "allow_anonymous": True,  # the demo is for trying the page: its link needs no Prolific ID
    }
    try:
        create_study(ctx, spec, study_id=DEMO_STUDY_ID)
    except Conflict:
        pass  # another process seeded it at the same moment
    return open_study(ctx, DEMO_STUDY_ID)


def study_row(s: Any, study_id: str, *, for_update: bool = False) -> StudyRow:
    study = repo.get_study(s, study_id=study_id, for_update=for_update)
    if study is None:
        raise NotFound(f"no study with id {study_id!r}")
    return study
