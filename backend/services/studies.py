"""Studies: validation of their specification, create/open/close/list, and the demo study."""

from __future__ import annotations

import re
import secrets
from collections.abc import Iterator
from typing import Any

from ..core import session as core
from ..core.domain import DINNER_OBJECTS, DINNER_TASK_FORMULAS, get_domain
from ..core.priors import NAMED_PRIORS
from ..core.puns import CRITERIA
from ..db import repository as repo
from ..db.tables import StudyRow
from ..errors import Conflict, InvalidFields, InvalidInput, NotFound
from .context import Context, commit, iso
from .instruments import INSTRUMENT_KINDS, instrument_fields
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


MAX_BALANCED_TASKS = 5  # 5! = 120 orders, each crossed with every condition


CODE = re.compile(r"^[A-Za-z0-9_\-]{1,64}$")


# What an experimenter may still change once participants can join (nothing they experience differently).
LIVE_FIELDS = ("name", "pilot", "completion_code", "screened_out_code", "completion_url", "timeout_minutes")


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


class _Problems:
    """Collects every unacceptable field of a study at once, each with its path and a plain message."""

    def __init__(self) -> None:
        self.errors: list[dict[str, str]] = []

    def add(self, field: str, message: str) -> None:
        self.errors.append({"field": field, "message": message})

    def raise_if_any(self) -> None:
        if self.errors:
            raise InvalidFields(self.errors)


def describe_formula(formula: str) -> dict[str, str]:
    """A custom task's formula in canonical form and in plain words; InvalidInput says what is wrong with it."""
    space = get_domain("dinner").clause_space
    try:
        mask = space.mask_of_formula(formula)
    except ValueError as exc:
        raise InvalidInput(f"ground_truth: {exc}") from exc
    return {"formula": space.text_of(mask), "description": space.describe(mask).capitalize() + "."}


def _check_tasks(tasks: Any, problems: _Problems) -> list[dict[str, Any]]:
    """Fill in the named tasks' formulas and check custom ones against the dinner clause templates."""
    if not isinstance(tasks, list) or not tasks:
        problems.add("tasks", "a study needs at least one task, e.g. [{'key': 'task1'}]")
        return []
    out = []
    for i, task in enumerate(tasks):
        if not isinstance(task, dict):
            problems.add(f"tasks.{i}", "expected a task with a key (task1, task2, custom or none)")
            continue
        key = task.get("key")
        if key not in TASK_KEYS:
            problems.add(f"tasks.{i}.key", f"is {key!r}; expected one of {', '.join(TASK_KEYS)}")
            continue
        formula = task.get("ground_truth") or None
        if key in TASK_FORMULAS:
            if formula and formula != TASK_FORMULAS[key]:
                problems.add(f"tasks.{i}.ground_truth", f"{key} has a fixed ground truth; leave this empty")
                continue
            formula = TASK_FORMULAS[key]
        elif key == "custom":
            if not formula:
                problems.add(f"tasks.{i}.ground_truth",
                             f"a custom task needs a formula over {', '.join(DINNER_OBJECTS)}, e.g. F(bowl) & "
                             "(!fork U knife)")
                continue
            try:
                formula = describe_formula(str(formula))["formula"]
            except InvalidInput as exc:
                problems.add(f"tasks.{i}.ground_truth", exc.message.removeprefix("ground_truth: "))
                continue
        elif formula:
            problems.add(f"tasks.{i}.ground_truth", "the key 'none' means the ground truth is unknown; "
                         "choose 'custom' to give a formula")
            continue
        out.append({
            "key": key,
            "ground_truth": formula,
            "name": task.get("name") or TASK_NAMES.get(key, f"Task {i + 1}"),
            "instructions": task.get("instructions") or TASK_INSTRUCTIONS.get(key)
            or ("" if formula is None else describe_formula(formula)["description"]),
        })
    return out


def _identified_items(items: Any, field: str, problems: _Problems) -> Iterator[tuple[int, dict[str, Any]]]:
    """The dict items of a list field with their positions; each needs an id not used by an earlier one."""
    seen: set[str] = set()
    for i, item in enumerate(items if isinstance(items, list) else []):
        if not isinstance(item, dict):
            continue
        item_id = item.get("id")
        if not isinstance(item_id, str) or not item_id or item_id in seen:
            problems.add(f"{field}.{i}.id", f"must be a non-empty id not used before, got {item_id!r}")
        seen.add(str(item_id))
        yield i, item


def _check_questionnaire(items: Any, problems: _Problems) -> list[dict[str, Any]]:
    """Items need a unique id, a text and a kind; attention checks also their expected answer (1-5)."""
    out = []
    for i, item in _identified_items(items, "questionnaire", problems):
        item_id, kind = item.get("id"), item.get("kind")
        if kind not in ITEM_KINDS:
            problems.add(f"questionnaire.{i}.kind", f"is {kind!r}; expected one of {', '.join(ITEM_KINDS)}")
            continue
        expected = item.get("expected")
        if kind == "attention" and (not isinstance(expected, int) or isinstance(expected, bool)
                                    or not 1 <= expected <= 5):
            problems.add(f"questionnaire.{i}.expected",
                         f"an attention check needs the expected answer, a whole number from 1 to 5, got {expected!r}")
        entry = {"id": item_id, "text": str(item.get("text", "")), "kind": kind,
                 "required": True if kind == "attention" else bool(item.get("required", True))}
        if kind == "attention":
            entry["expected"] = expected
        entry.update(instrument_fields(item, f"questionnaire.{i}", problems))  # standard questionnaires' fields
        out.append(entry)
    return out


def _check_quiz(items: Any, problems: _Problems) -> list[dict[str, Any]]:
    """Comprehension quiz items: a unique id, a question, at least two options and the index of the correct one."""
    out = []
    for i, item in _identified_items(items, "quiz", problems):
        item_id, options, correct = item.get("id"), item.get("options"), item.get("correct")
        if not isinstance(options, list) or len(options) < 2 or not all(isinstance(o, str) and o for o in options):
            problems.add(f"quiz.{i}.options", "expected at least two non-empty answer options")
            continue
        if not isinstance(correct, int) or isinstance(correct, bool) or not 0 <= correct < len(options):
            problems.add(f"quiz.{i}.correct", f"expected the number of the correct option, from 0 to "
                         f"{len(options) - 1}, got {correct!r}")
            continue
        out.append({"id": item_id, "text": str(item.get("text", "")), "options": list(options), "correct": correct})
    return out


def _whole(problems: _Problems, name: str, value: Any, low: int, high: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        problems.add(name, f"must be a whole number from {low} to {high}, got {value!r}")


def _study_values(spec: dict[str, Any], problems: _Problems | None = None) -> dict[str, Any]:
    """Validated column values of a new study; InvalidFields lists every unacceptable field at once."""
    problems = problems or _Problems()
    conditions = spec.get("conditions") or []
    if (not isinstance(conditions, list) or not conditions or len(set(map(str, conditions))) != len(conditions)
            or any(c not in core.PROTOCOLS for c in conditions)):
        problems.add("conditions", f"must be distinct protocols from {', '.join(core.PROTOCOLS)}, got {conditions!r}")
    assignment = spec.get("assignment", "balanced")
    if assignment not in ASSIGNMENTS:
        problems.add("assignment", f"is {assignment!r}; expected one of {', '.join(ASSIGNMENTS)}")
    if spec.get("prior", core.DEFAULT_PRIOR) not in NAMED_PRIORS:
        problems.add("prior", f"is {spec.get('prior')!r}; expected one of {', '.join(NAMED_PRIORS)}")
    if spec.get("criterion", "min-regret") not in CRITERIA:
        problems.add("criterion", f"is {spec.get('criterion')!r}; expected one of {', '.join(CRITERIA)}")
    counts = {name: spec.get(name, default) for name, default in
              (("n_practice", 1), ("n_demonstrations", 2), ("n_queries", 3), ("n_tests", 3))}
    for name, value in counts.items():
        _whole(problems, name, value, 0, 20)
    speed = spec.get("robot_speed", 1.0)
    low, high = ROBOT_SPEEDS
    if isinstance(speed, bool) or not isinstance(speed, (int, float)) or not low <= speed <= high:
        problems.add("robot_speed", f"must be a number from {low:g} to {high:g} (how much faster than real time "
                     f"the robot's motion is shown), got {speed!r}")
    url = spec.get("completion_url")
    if url is not None and not str(url).startswith(("https://", "http://")):
        problems.add("completion_url", f"must start with https:// or http://, got {url!r}")
    codes = {name: spec.get(name) or None for name in ("completion_code", "screened_out_code")}
    for name, code in codes.items():
        if code is not None and not CODE.match(str(code)):
            problems.add(name, f"must be letters, digits, - or _ (at most 64), got {code!r}")
    task_order = spec.get("task_order", "fixed")
    tasks = _check_tasks(spec.get("tasks"), problems)
    if task_order not in TASK_ORDERS:
        problems.add("task_order", f"is {task_order!r}; expected one of {', '.join(TASK_ORDERS)}")
    elif task_order == "balanced" and len(tasks) > MAX_BALANCED_TASKS:
        problems.add("task_order", f"balanced uses every order of the tasks; at most {MAX_BALANCED_TASKS} tasks "
                     f"({len(tasks)} given): use random instead")
    attempts = spec.get("quiz_max_attempts", 2)
    _whole(problems, "quiz_max_attempts", attempts, 1, 10)
    timeout = spec.get("timeout_minutes")
    if timeout is not None:
        _whole(problems, "timeout_minutes", timeout, 1, 1440)
    values = {
        "name": spec.get("name") or "Untitled study",
        "tasks": tasks,
        "conditions": conditions,
        "assignment": assignment,
        **counts,
        "prior": spec.get("prior", core.DEFAULT_PRIOR),
        "criterion": spec.get("criterion", "min-regret"),
        "questionnaire": _check_questionnaire(spec.get("questionnaire") or [], problems),
        "consent_text": spec.get("consent_text") or DEFAULT_CONSENT,
        "consent_version": spec.get("consent_version") or "1",
        "completion_url": url,
        "pilot": bool(spec.get("pilot", False)),
        **codes,
        "task_order": task_order,
        "quiz": _check_quiz(spec.get("quiz") or [], problems),
        "quiz_max_attempts": attempts,
        "timeout_minutes": timeout,
        "robot_speed": float(speed) if isinstance(speed, (int, float)) else 1.0,
        **check_page_settings(spec, problems),
        "status": "draft",
    }
    problems.raise_if_any()
    return values


def study_problems(spec: dict[str, Any]) -> list[dict[str, str]]:
    """Every unacceptable field of a study specification (empty if it is acceptable)."""
    try:
        _study_values(spec)
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
        "completion_url": study.completion_url, "completion_code": study.completion_code,
        "screened_out_code": study.screened_out_code, "task_order": study.task_order, "quiz": study.quiz,
        "quiz_max_attempts": study.quiz_max_attempts, "timeout_minutes": study.timeout_minutes,
        "robot_speed": study.robot_speed, **page_settings_view(study),
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
    spec = {k: v for k, v in study.items() if k not in ("id", "status", "created_at", "updated_at")}
    spec["tasks"] = [{k: v for k, v in t.items() if not (k == "ground_truth" and t["key"] in TASK_FORMULAS)}
                     for t in study["tasks"]]
    return spec


def update_study(ctx: Context, study_id: str, changes: dict[str, Any]) -> dict[str, Any]:
    """Edit a study: any field while it is a draft; once opened, only LIVE_FIELDS (the rest would differ
    between participants). Fields not named in changes keep their stored values."""
    with ctx.db.write() as s:
        study = study_row(s, study_id, for_update=True)
        current = study_view(study)
        if study.status != "draft":
            frozen = sorted(k for k, v in changes.items() if k not in LIVE_FIELDS and v != current.get(k))
            if frozen:
                raise Conflict(f"study {study_id!r} is {study.status}: {', '.join(frozen)} can change only while it "
                               f"is a draft (clone it to make a draft copy); expected only {', '.join(LIVE_FIELDS)}")
        values = _study_values({**editable_spec(current), **changes})
        values.pop("status")
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
