"""The one validator of a study definition, used by the API (its schema is this model) and by the services.

Each field's type and bounds are declared once, in the pydantic model below; rules that tie fields together (a
custom task's formula, distinct conditions, quiz answers among the options, attention checks with an expected
answer, unique item ids) are checked after it. Every problem is reported at once, each with its field's path
and a plain message (plain_words.py).
"""

from __future__ import annotations

from collections.abc import Iterator
import re
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, field_validator

from ..core import session as core
from ..core.belief import MAX_FLIP_RATE
from ..core.domain import DINNER_OBJECTS, DINNER_TASK_FORMULAS, get_domain, objects_task
from ..core.learner_seam import ENUMERATED_UP_TO, EXACT_CRITERIA, exact_problems
from ..core.ltl import to_text
from ..core.priors import NAMED_PRIORS
from ..core.puns import CRITERIA
from ..errors import InvalidFields, InvalidInput
from ..scenes import layout as scene_layout
from ..scenes.spec import (COLOUR_PATTERN, DEFAULT_SIZES, MAX_OBJECTS, MIN_OBJECTS, NAME_PATTERN, SHAPES, SIZE_MEANING,
                           SIZE_RANGES, SceneSpec, name_problem)
from .instruments import INSTRUMENTS, instrument_fields
from .page_settings import ConsentFormIn, check_page_settings
from .plain_words import field_errors, number_ranges, shown

MAX_BALANCED_TASKS = 5  # 5! = 120 orders, each crossed with every condition
# A study takes MIN_OBJECTS to MAX_OBJECTS objects (scenes.spec). Up to five its learner enumerates every formula
# (core.hypotheses); past five the exact factorised learner answers (core.exact, through core.learner_seam), which
# offers fewer settings (learner_seam.exact_problems).
MAX_PLACES = 100_000  # participants a study may take
CODE_PATTERN = r"^[A-Za-z0-9_\-]+$"
ID_PATTERN = r"^[A-Za-z0-9_\-]+$"

# What each pattern means, for its error message (field paths with list positions as *).
PATTERN_HINTS = {
    **{name: "letters, digits, - or _ (as in Prolific's completion codes)" for name in (
        "completion_code", "declined_consent_code", "failed_quiz_code", "failed_attention_code", "timed_out_code",
        "withdrew_code", "screened_out_code")},
    "completion_url": "a web address starting with https:// or http://, without spaces",
    "tasks.*.ground_truth": (f"template clauses F(p), G(!p) or (!b U a) over {', '.join(DINNER_OBJECTS)}, "
                             "joined by &, e.g. F(bowl) & (!fork U knife)"),
    "formula": (f"template clauses F(p), G(!p) or (!b U a) over {', '.join(DINNER_OBJECTS)}, joined by &, "
                "e.g. F(bowl) & (!fork U knife)"),
    "quiz.*.options.*": "some text",
    "objects.*.name": "lower-case letters, digits and _, starting with a letter (e.g. lunch_box)",
    "objects.*.colour": "a colour as #rrggbb, e.g. #3366cc",
    "questionnaire.*.id": "letters, digits, - or _",
    "quiz.*.id": "letters, digits, - or _",
}


def integral(value: Any) -> Any:
    """18.0 is the whole number 18 (JSON and its schema do not tell them apart), also inside a dict or list;
    anything else is left to the field's own check."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, dict):
        return {k: integral(v) for k, v in value.items()}
    if isinstance(value, list):
        return [integral(v) for v in value]
    return value


class Definition(BaseModel):
    """Unknown fields are an error: a typo should not pass silently."""

    model_config = ConfigDict(extra="forbid", strict=True)

    @field_validator("*", mode="before")
    @classmethod
    def _whole_numbers(cls, value: Any) -> Any:
        return integral(value)


def Code(meaning: str) -> Any:  # noqa: N802 (a Field factory, named like the type it describes)
    """An optional completion code for one outcome; the completion URL's {code} is replaced with it."""
    return Field(None, min_length=1, max_length=64, pattern=CODE_PATTERN, description=f"code for those who {meaning}")


def formula_pattern(task: str = "dinner") -> str:
    """A regular expression of the formulas a custom task takes: template clauses of the task joined by & (or true,
    no clause at all)."""
    space = get_domain(task).clause_space
    clauses = sorted((re.escape(to_text(c.formula())).replace(r"\ ", r"\s+") for c in space.clauses), key=len,
                     reverse=True)
    one = "(?:" + "|".join(clauses) + ")"
    return rf"^\s*(?:true|{one}(?:\s*&\s*{one})*)\s*$"


FORMULA_PATTERN = formula_pattern()
# Template clauses over any object names: what a custom task's formula looks like in a study with its own objects.
_NAME = r"[a-z][a-z0-9_]*"
_CLAUSE = rf"(?:G\(\s*!\s*{_NAME}\s*\)|F\(\s*{_NAME}\s*\)|\(\s*!\s*{_NAME}\s+U\s+{_NAME}\s*\))"
ANY_OBJECTS_FORMULA_PATTERN = rf"^\s*(?:true|{_CLAUSE}(?:\s*&\s*{_CLAUSE})*)\s*$"


def when(condition: dict[str, Any], then: dict[str, Any]) -> dict[str, Any]:
    """JSON Schema's if/then over an object's properties (generators of clients ignore it; validators apply it)."""
    return {"if": {"properties": condition, "required": list(condition)}, "then": then}


def _task_rules() -> list[dict[str, Any]]:
    """What the hand-written rules below say about a task, in JSON Schema (so the schema is the validator); a custom
    task's formula over the dinner objects is the study's rule (_study_rules), as its objects decide it."""
    named = [when({"key": {"const": key}}, {"properties": {"ground_truth": {"enum": [None, "", formula]}}})
             for key, formula in DINNER_TASK_FORMULAS.items()]
    return [*named,
            when({"key": {"const": "custom"}}, {"properties": {"ground_truth": {
                "type": "string", "pattern": ANY_OBJECTS_FORMULA_PATTERN}}, "required": ["ground_truth"]}),
            when({"key": {"const": "none"}}, {"properties": {"ground_truth": {"enum": [None, ""]}}})]


def _study_rules() -> list[dict[str, Any]]:
    """The study-wide rules in JSON Schema: balanced orders' limit; with the dinner objects a custom formula names
    them; with the study's own objects only custom and none tasks (the paper's two are the dinner table's); past
    five objects only the exact learner's settings (core.learner_seam.exact_problems)."""
    dinner = {"anyOf": [{"not": {"required": ["objects"]}},
                        {"properties": {"objects": {"type": "null"}}, "required": ["objects"]}]}
    own = {"properties": {"objects": {"type": "array"}}, "required": ["objects"]}
    dinner_formula = when({"key": {"const": "custom"}}, {"properties": {"ground_truth": {"pattern": FORMULA_PATTERN}}})
    return [when({"task_order": {"const": "balanced"}}, {"properties": {"tasks": {"maxItems": MAX_BALANCED_TASKS}}}),
            {"if": dinner, "then": {"properties": {"tasks": {"items": dinner_formula}}}},
            {"if": own, "then": {"properties": {"tasks": {"items": {"properties": {
                "key": {"enum": ["custom", "none"]}}}}}}},
            when({"objects": {"type": "array", "minItems": ENUMERATED_UP_TO + 1}}, {"properties": {
                "prior": {"enum": [name for name in NAMED_PRIORS if not exact_problems(name)]},
                "flip_rate": {"const": 0}, "criterion": {"enum": list(EXACT_CRITERIA)}}})]


def _object_rules() -> list[dict[str, Any]]:
    """Each shape's size range, in JSON Schema."""
    return [when({"shape": {"const": shape}}, {"properties": {"size": {"anyOf": [
        {"type": "null"}, {"type": "number", "minimum": low, "maximum": high}]}}})
        for shape, (low, high) in SIZE_RANGES.items()]


class SlotIn(Definition):
    """Where an object goes on Table B, as the goal picture shows the table from above (the robot at the top)."""

    x: float = Field(ge=-24, le=24, description="centimetres right of Table B's centre")
    y: float = Field(ge=-22, le=22, description="centimetres from Table B's centre towards the robot")


class ObjectIn(Definition):
    """One of a study's own objects: its name (also its proposition), shape, colour, size and goal slot."""

    model_config = ConfigDict(json_schema_extra={"allOf": _object_rules()})  # type: ignore[dict-item]

    name: str = Field(min_length=1, max_length=32, pattern=NAME_PATTERN, description="e.g. lunch_box")
    shape: Literal[SHAPES] = Field(description="how it looks and how the robot holds it")  # type: ignore[valid-type]
    colour: str = Field("#888888", pattern=COLOUR_PATTERN, description="#rrggbb")
    size: float | None = Field(None, gt=0, description="centimetres: a plate's, bowl's, cup's or glass's diameter, "
                               "a utensil's length, a box's side; each shape has its range (empty: a typical size)")
    slot: SlotIn


class TaskIn(Definition):
    """One task of a study: a named dinner task, a custom formula, or none (ground truth unknown)."""

    model_config = ConfigDict(json_schema_extra={"allOf": _task_rules()})  # type: ignore[dict-item]

    key: Literal["task1", "task2", "custom", "none"]
    ground_truth: str | None = Field(None, max_length=2000, description="custom tasks only: an LTL formula over "
                                     "the dinner objects, e.g. F(bowl) & (!fork U knife)")
    name: str | None = Field(None, max_length=200)
    instructions: str | None = Field(None, max_length=5000)


class ItemIn(Definition):
    """A questionnaire item; an attention check is shown as a 1-5 agreement item with an expected answer."""

    model_config = ConfigDict(json_schema_extra=when(
        {"kind": {"const": "attention"}}, {"properties": {"expected": {"type": "integer"}}, "required": ["expected"]}))

    id: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    text: str = Field(max_length=2000)
    kind: Literal["likert5", "rating10", "text", "attention", "anchored5", "anchored7", "tlx21"]
    required: bool = True
    expected: int | None = Field(None, ge=1, le=5,
                                 description="attention checks (shown as a 1-5 agreement scale): the expected answer")
    anchors: list[Annotated[str, Field(min_length=1, max_length=60)]] | None = Field(
        None, min_length=2, max_length=2, description="anchored scales (standard questionnaires): the end labels")
    instrument: Literal[tuple(INSTRUMENTS)] | None = Field(  # type: ignore[valid-type]
        None, description="the standard questionnaire the item is from (GET /api/v1/instruments)")
    instrument_item: str | None = Field(None, max_length=64, description="the item's key in that questionnaire")


class QuizItemIn(Definition):
    """A comprehension-quiz question with its options and the correct one."""

    # correct is the number of one of the options: for each number of options, its bound
    model_config = ConfigDict(json_schema_extra={"allOf": [
        when({"options": {"maxItems": n}}, {"properties": {"correct": {"maximum": n - 1}}}) for n in range(2, 10)]})

    id: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    text: str = Field(min_length=1, max_length=2000)
    options: list[Annotated[str, Field(min_length=1, max_length=500, pattern=r"\S")]] = Field(min_length=2,
                                                                                              max_length=10)
    correct: int = Field(ge=0, le=9, description="index (from 0) of the correct option")


class StudyIn(Definition):
    """A study definition: what creates a study (and what GET /studies/{id}/spec gives back)."""

    model_config = ConfigDict(json_schema_extra={"allOf": _study_rules()})  # type: ignore[dict-item]

    name: str = Field("Untitled study", max_length=200)
    tasks: list[TaskIn] = Field(min_length=1, max_length=10)
    conditions: list[Literal["active", "random", "batch"]] = Field(["active"], min_length=1, max_length=3,
                                                                   json_schema_extra={"uniqueItems": True})
    assignment: Literal["random", "balanced"] = "balanced"
    n_practice: int = Field(1, ge=0, le=20)
    n_demonstrations: int = Field(2, ge=0, le=20)
    n_queries: int = Field(3, ge=0, le=20)
    n_tests: int = Field(3, ge=0, le=20)
    prior: Literal[tuple(NAMED_PRIORS)] = core.DEFAULT_PRIOR  # type: ignore[valid-type]
    criterion: Literal[CRITERIA] = "min-regret"  # type: ignore[valid-type]
    questionnaire: list[ItemIn] = Field(default_factory=list, max_length=100)
    consent_text: str | None = Field(None, max_length=20000)
    consent_version: str | None = Field(None, max_length=64)
    completion_url: str | None = Field(None, max_length=500, pattern=r"^https?://\S+$",
                                       description="redirect at the end; {code} is replaced with the outcome's code")
    pilot: bool = False
    completion_code: str | None = Code("completed the study (on Prolific: approve)")
    declined_consent_code: str | None = Code("declined consent (on Prolific: ask them to return)")
    failed_quiz_code: str | None = Code("failed the comprehension quiz (on Prolific: screen out or return)")
    failed_attention_code: str | None = Code("finished but failed an attention check (on Prolific: review, "
                                             "reject per its attention-check policy)")
    timed_out_code: str | None = Code("were idle past timeout_minutes (on Prolific: ask them to return)")
    withdrew_code: str | None = Code("withdrew after consenting (usually empty: Prolific counts them as returned)")
    screened_out_code: str | None = Code("were screened out, for outcomes without their own code (older studies)")
    task_order: Literal["fixed", "random", "balanced"] = "fixed"
    quiz: list[QuizItemIn] = Field(default_factory=list, max_length=20)
    quiz_max_attempts: int = Field(2, ge=1, le=10)
    timeout_minutes: int | None = Field(None, ge=1, le=1440)
    robot_speed: float = Field(1.0, ge=1.0, le=3.0, description="the robot's motion is shown this many times faster "
                               "than real time (recordings keep real time)")
    consent_form: ConsentFormIn | None = Field(None, description="the structured consent form's sections")
    allow_anonymous: bool = Field(False, description="a link without PROLIFIC_PID joins without asking for an id")
    quiz_feedback: bool = Field(True, description="a failed quiz names the wrong answers")
    flip_rate: float = Field(0.0, ge=0.0, lt=MAX_FLIP_RATE, description="the noise-aware learner: the probability "
                             "it assumes each verdict is wrong (0: the authors' learner, every verdict certain)")
    places: int | None = Field(None, ge=1, le=MAX_PLACES, description="participants the study takes, counted as "
                               "Prolific does (finished plus under way); then joining answers 409 (empty: no limit)")
    objects: list[ObjectIn] | None = Field(None, min_length=MIN_OBJECTS, max_length=MAX_OBJECTS, description=(
        "the study's own objects and goal layout (empty: the paper's dinner table); their names are the "
        f"propositions of its tasks' formulas; past {ENUMERATED_UP_TO} the exact learner answers, with the "
        "authors' likelihood (flip_rate 0), a chains or total-order prior and the min-regret criterion"))


STUDY_FIELDS = tuple(StudyIn.model_fields)
STUDY_RANGES = number_ranges(StudyIn)


def study_task(objects: list[str] | tuple[str, ...] | None) -> str:
    """The learner's task of a study: its own objects (core.domain.objects_task), or the dinner table."""
    return "dinner" if not objects else objects_task(tuple(objects))


def describe_formula(formula: str, objects: list[str] | tuple[str, ...] | None = None) -> dict[str, str]:
    """A custom task's formula in canonical form and in plain words (over the study's objects, else the dinner
    table's); InvalidInput says what is wrong with it."""
    space = get_domain(study_task(objects)).clause_space
    try:
        mask = space.mask_of_formula(formula)
    except ValueError as exc:
        raise InvalidInput(f"ground_truth: {exc}") from exc
    return {"formula": space.text_of(mask), "description": space.describe(mask).capitalize() + "."}


def _dicts(items: Any) -> Iterator[tuple[int, dict[str, Any]]]:
    for i, item in enumerate(items if isinstance(items, list) else []):
        if isinstance(item, dict):
            yield i, item


def _object_names(spec: dict[str, Any]) -> tuple[str, ...] | None:
    """The study's own object names if its objects are well-formed and distinct (None: the dinner table, or objects
    whose own problems are reported instead)."""
    objects = spec.get("objects")
    if not isinstance(objects, list) or not objects:
        return None
    names = tuple(o.get("name") for o in objects if isinstance(o, dict) and isinstance(o.get("name"), str))
    if len(names) != len(objects) or len(set(names)) != len(names) or not MIN_OBJECTS <= len(names) <= MAX_OBJECTS \
            or not all(isinstance(n, str) and name_problem(n) is None for n in names):
        return None
    return names  # type: ignore[return-value]


def _example(names: tuple[str, ...]) -> str:
    return f"F({names[0]}) & (!{names[-1]} U {names[0]})"


def _task_problems(spec: dict[str, Any]) -> Iterator[tuple[str, str]]:
    names = _object_names(spec)
    own = isinstance(spec.get("objects"), list) and bool(spec.get("objects"))
    objects = names or DINNER_OBJECTS
    example = _example(names) if names else "F(bowl) & (!fork U knife)"
    hint = f"template clauses F(p), G(!p) or (!b U a) over {', '.join(objects)}, joined by &, e.g. {example}"
    for i, task in _dicts(spec.get("tasks")):
        key, formula = task.get("key"), task.get("ground_truth") or None
        if not isinstance(key, str) or not isinstance(formula, (str, type(None))):
            continue  # the model names a key or formula of the wrong kind
        where = f"tasks.{i}.ground_truth"
        if own and key in DINNER_TASK_FORMULAS:
            yield f"tasks.{i}.key", (f"{key} is the dinner table's task; a study with its own objects has custom tasks "
                                     "(a formula over its objects) or none")
        elif key in DINNER_TASK_FORMULAS and formula and formula != DINNER_TASK_FORMULAS[key]:
            yield where, f"{key} has a fixed ground truth; leave this empty"
        elif key == "custom" and not formula:
            yield where, f"a custom task needs a formula over {', '.join(objects)}, e.g. {example}"
        elif key == "custom" and formula is not None and own and names is None:
            continue  # the objects' own problems come first
        elif key == "custom" and formula is not None and not re.match(formula_pattern(study_task(names)), formula):
            yield where, f"must be {hint}, got {shown(formula)}{_unknown_objects(formula, objects)}"
        elif key == "custom" and formula is not None:
            try:
                describe_formula(formula, names)
            except InvalidInput as exc:
                yield where, exc.message.removeprefix("ground_truth: ")
        elif key == "none" and formula:
            yield where, "the key 'none' means the ground truth is unknown; choose 'custom' to give a formula"


def _unknown_objects(formula: str, objects: tuple[str, ...]) -> str:
    """'; it names ..., which the study does not have' for a formula over objects the study lacks (else '')."""
    named = set(re.findall(r"[a-z][a-z0-9_]*", formula)) - {"true", "false"}
    unknown = sorted(named - set(objects))
    if not unknown:
        return ""
    return f"; it names {', '.join(unknown)}, which {'is not an object' if len(unknown) == 1 else 'are not objects'} " \
        "of this study"


def _object_problems(spec: dict[str, Any]) -> Iterator[tuple[str, str]]:
    """Each object's size within its shape's range, names a formula can use, and the scene: distinct names, slots on
    Table B clear of each other and within the arm's reach, room for every object on Table A."""
    objects = spec.get("objects")
    if not isinstance(objects, list) or not objects:
        return
    if ENUMERATED_UP_TO < len(objects) <= MAX_OBJECTS:  # the exact learner's settings only
        prior = spec.get("prior", core.DEFAULT_PRIOR)
        flip_rate = spec.get("flip_rate", 0.0)
        criterion = spec.get("criterion", "min-regret")
        if isinstance(prior, str) and prior in NAMED_PRIORS and isinstance(criterion, str) and criterion in CRITERIA \
                and isinstance(flip_rate, (int, float)) and not isinstance(flip_rate, bool):  # else the model says
            for field, why in exact_problems(prior, float(flip_rate), criterion):
                yield field, f"{why} ({len(objects)} objects given)"
    valid = True
    seen: dict[str, int] = {}
    for i, o in _dicts(objects):
        name, shape, size = o.get("name"), o.get("shape"), o.get("size")
        if isinstance(name, str) and name in seen:
            yield f"objects.{i}.name", (f"{name!r} is already the name of object {seen[name] + 1}; each object needs "
                                        "its own name")
            valid = False
        if isinstance(name, str):
            seen.setdefault(name, i)
        if isinstance(name, str) and re.match(NAME_PATTERN, name) and name_problem(name):
            yield f"objects.{i}.name", name_problem(name) or ""
            valid = False
        if isinstance(shape, str) and shape in SIZE_RANGES and isinstance(size, (int, float)) \
                and not isinstance(size, bool):
            low, high = SIZE_RANGES[shape]
            if not low <= size <= high:
                yield f"objects.{i}.size", (f"a {shape}'s {SIZE_MEANING[shape]} must be {low:g} to {high:g} cm, "
                                            f"got {size:g}")
                valid = False
    if not valid:
        return
    try:
        model = TypeAdapter(list[ObjectIn]).validate_python(objects)
    except ValidationError:
        return  # the model names the fields
    scene = scene_spec([o.model_dump() for o in model])
    yield from scene_layout.scene_problems(scene)


def scene_spec(objects: list[dict[str, Any]]) -> SceneSpec:
    """The scene specification of validated objects (a missing size is the shape's typical one)."""
    return SceneSpec.from_json([{**o, "size": o.get("size") or DEFAULT_SIZES[o["shape"]]} for o in objects])


def _item_problems(spec: dict[str, Any]) -> Iterator[tuple[str, str]]:
    for field in ("questionnaire", "quiz"):
        seen: set[Any] = set()
        for i, item in _dicts(spec.get(field)):
            item_id = item.get("id")
            if not isinstance(item_id, str):
                continue  # the model names a missing or non-text id
            if item_id in seen:
                yield f"{field}.{i}.id", f"{shown(item_id)} is already the id of an earlier item; each needs its own"
            seen.add(item_id)
    for i, item in _dicts(spec.get("questionnaire")):
        if item.get("kind") == "attention" and item.get("expected") is None:
            yield f"questionnaire.{i}.expected", "an attention check needs the expected answer, a whole number 1-5"
    for i, item in _dicts(spec.get("quiz")):
        options, correct = item.get("options"), item.get("correct")
        if isinstance(options, list) and isinstance(correct, int) and not isinstance(correct, bool) \
                and len(options) >= 2 and not 0 <= correct < len(options):
            yield f"quiz.{i}.correct", (f"must be the number of the correct option, from 0 to {len(options) - 1}, "
                                        f"got {correct}")


def _study_problems(spec: dict[str, Any]) -> Iterator[tuple[str, str]]:
    conditions = spec.get("conditions")
    if isinstance(conditions, list) and len({str(c) for c in conditions}) != len(conditions):
        yield "conditions", "each protocol may be listed once"
    tasks = spec.get("tasks")
    if spec.get("task_order") == "balanced" and isinstance(tasks, list) and len(tasks) > MAX_BALANCED_TASKS:
        yield "task_order", (f"balanced uses every order of the tasks; at most {MAX_BALANCED_TASKS} tasks "
                             f"({len(tasks)} given): use random instead")
    yield from _object_problems(spec)
    yield from _task_problems(spec)
    yield from _item_problems(spec)
    problems = ProblemList()
    check_page_settings(spec, problems)  # the consent form's sections and the page's flags
    items = spec.get("questionnaire")
    for i, item in enumerate(items if isinstance(items, list) else []):
        if isinstance(item, dict):
            instrument_fields(item, f"questionnaire.{i}", problems)  # standard questionnaires' fields
    yield from problems.found


class ProblemList:
    """Collects (field, message) problems from the checks that take a problems object."""

    def __init__(self) -> None:
        self.found: list[tuple[str, str]] = []

    def add(self, field: str, message: str) -> None:
        """Note one unacceptable field."""
        self.found.append((field, message))


def validate_study(spec: Any) -> StudyIn:
    """The study definition checked field by field; InvalidFields lists every unacceptable field at once."""
    if not isinstance(spec, dict):
        raise InvalidFields([{"field": "body", "message": "expected a study definition (an object with tasks)"}])
    model = None
    try:
        model = StudyIn.model_validate(spec)
        errors = []
    except ValidationError as exc:
        errors = field_errors(exc.errors(), PATTERN_HINTS, STUDY_RANGES)
    bad = {e["field"] for e in errors}
    for field, message in _study_problems(spec):
        if not any(field == f or field.startswith(f + ".") for f in bad):
            errors.append({"field": field, "message": message})
            bad.add(field)
    if errors or model is None:
        raise InvalidFields(errors)
    return model
