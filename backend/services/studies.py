"""Studies: validation of their specification, create/open/close/list, and the demo study."""

from __future__ import annotations

import secrets
from typing import Any

from ..core import session as core
from ..core.domain import DINNER_OBJECTS, DINNER_TASK_FORMULAS, get_domain
from ..core.priors import NAMED_PRIORS
from ..core.puns import CRITERIA
from ..db import repository as repo
from ..db.tables import StudyRow
from ..errors import Conflict, InvalidInput, NotFound
from .context import Context, commit, iso

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


ITEM_KINDS = {"likert5": (1, 5), "rating10": (1, 10), "text": None}


DEMO_STUDY_ID = "demo"


ROBOT_SPEEDS = (1.0, 3.0)  # a study shows the robot's motion 1x to 3x faster than recorded (recordings keep real time)


DEFAULT_CONSENT = (
    "You will teach a simulated robot to set a table by showing it and by judging its attempts. "
    "Your actions and answers are recorded without your name. You may stop at any time."
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


def _check_tasks(tasks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Fill in the named tasks' formulas and check custom ones against the dinner clause templates."""
    if not tasks:
        raise InvalidInput("a study needs at least one task; expected e.g. [{'key': 'task1'}]")
    space = get_domain("dinner").clause_space
    out = []
    for i, task in enumerate(tasks):
        key = task.get("key")
        if key not in TASK_KEYS:
            raise InvalidInput(f"tasks[{i}].key is {key!r}; expected one of {', '.join(TASK_KEYS)}")
        formula = task.get("ground_truth") or None
        if key in TASK_FORMULAS:
            if formula:
                raise InvalidInput(f"tasks[{i}] is {key}, whose ground truth is fixed; leave ground_truth empty")
            formula = TASK_FORMULAS[key]
        elif key == "custom":
            if not formula:
                raise InvalidInput(f"tasks[{i}] is custom and needs a ground_truth formula over "
                                   f"{', '.join(DINNER_OBJECTS)}")
            try:
                formula = space.text_of(space.mask_of_formula(formula))
            except ValueError as exc:
                raise InvalidInput(f"tasks[{i}].ground_truth: {exc}") from exc
        elif formula:
            raise InvalidInput(f"tasks[{i}] has key 'none' (ground truth unknown); use 'custom' to give a formula")
        mask = None if formula is None else space.mask_of_formula(formula)
        out.append({
            "key": key,
            "ground_truth": formula,
            "name": task.get("name") or TASK_NAMES.get(key, f"Task {i + 1}"),
            "instructions": task.get("instructions")
            or TASK_INSTRUCTIONS.get(key)
            or ("" if mask is None else space.describe(mask).capitalize() + "."),
        })
    return out


def _check_questionnaire(items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Items need a unique id, a text and a kind of likert5, rating10 or text."""
    seen: set[str] = set()
    out = []
    for i, item in enumerate(items):
        item_id, kind = item.get("id"), item.get("kind")
        if not isinstance(item_id, str) or not item_id or item_id in seen:
            raise InvalidInput(f"questionnaire[{i}].id must be a non-empty id not used before, got {item_id!r}")
        if kind not in ITEM_KINDS:
            raise InvalidInput(f"questionnaire[{i}].kind is {kind!r}; expected one of {', '.join(ITEM_KINDS)}")
        seen.add(item_id)
        out.append({"id": item_id, "text": str(item.get("text", "")), "kind": kind,
                    "required": bool(item.get("required", True))})
    return out


def _study_values(spec: dict[str, Any]) -> dict[str, Any]:
    """Validated column values of a new study."""
    conditions = list(spec.get("conditions") or [])
    if not conditions or len(set(conditions)) != len(conditions) or any(c not in core.PROTOCOLS for c in conditions):
        raise InvalidInput(f"conditions must be distinct protocols from {', '.join(core.PROTOCOLS)}, "
                           f"got {conditions!r}")
    assignment = spec.get("assignment", "balanced")
    if assignment not in ASSIGNMENTS:
        raise InvalidInput(f"assignment is {assignment!r}; expected one of {', '.join(ASSIGNMENTS)}")
    if spec.get("prior", core.DEFAULT_PRIOR) not in NAMED_PRIORS:
        raise InvalidInput(f"prior is {spec.get('prior')!r}; expected one of {', '.join(NAMED_PRIORS)}")
    if spec.get("criterion", "min-regret") not in CRITERIA:
        raise InvalidInput(f"criterion is {spec.get('criterion')!r}; expected one of {', '.join(CRITERIA)}")
    counts = {name: spec.get(name, default) for name, default in
              (("n_practice", 1), ("n_demonstrations", 2), ("n_queries", 3), ("n_tests", 3))}
    for name, value in counts.items():
        if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 20:
            raise InvalidInput(f"{name} must be a whole number from 0 to 20, got {value!r}")
    speed = spec.get("robot_speed", 1.0)
    low, high = ROBOT_SPEEDS
    if isinstance(speed, bool) or not isinstance(speed, (int, float)) or not low <= speed <= high:
        raise InvalidInput(f"robot_speed must be a number from {ROBOT_SPEEDS[0]:g} to {ROBOT_SPEEDS[1]:g} "
                           f"(how much faster than real time the robot's motion is shown), got {speed!r}")
    url = spec.get("completion_url")
    if url is not None and not str(url).startswith(("https://", "http://")):
        raise InvalidInput(f"completion_url must start with https:// or http://, got {url!r}")
    return {
        "name": spec.get("name") or "Untitled study",
        "tasks": _check_tasks(list(spec.get("tasks") or [])),
        "conditions": conditions,
        "assignment": assignment,
        **counts,
        "prior": spec.get("prior", core.DEFAULT_PRIOR),
        "criterion": spec.get("criterion", "min-regret"),
        "questionnaire": _check_questionnaire(list(spec.get("questionnaire") or [])),
        "consent_text": spec.get("consent_text") or DEFAULT_CONSENT,
        "consent_version": spec.get("consent_version") or "1",
        "completion_url": url,
        "pilot": bool(spec.get("pilot", False)),
        "robot_speed": float(speed),
        "status": "draft",
    }


def study_view(study: StudyRow) -> dict[str, Any]:
    """A study as the experimenter API shows it."""
    return {
        "id": study.id, "name": study.name, "status": study.status, "pilot": study.pilot,
        "tasks": study.tasks, "conditions": study.conditions, "assignment": study.assignment,
        "n_practice": study.n_practice, "n_demonstrations": study.n_demonstrations,
        "n_queries": study.n_queries, "n_tests": study.n_tests, "prior": study.prior,
        "criterion": study.criterion, "questionnaire": study.questionnaire,
        "consent_text": study.consent_text, "consent_version": study.consent_version,
        "completion_url": study.completion_url, "robot_speed": study.robot_speed,
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


def list_studies(ctx: Context) -> list[dict[str, Any]]:
    """Every study."""
    with ctx.db.read() as s:
        return [study_view(st) for st in repo.list_studies(s)]


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
    }
    try:
        create_study(ctx, spec, study_id=DEMO_STUDY_ID)
    except Conflict:
        pass  # another process seeded it at the same moment
    return open_study(ctx, DEMO_STUDY_ID)


def study_row(s: Any, study_id: str) -> StudyRow:
    study = repo.get_study(s, study_id=study_id)
    if study is None:
        raise NotFound(f"no study with id {study_id!r}")
    return study
