"""Request and response models of the REST API (kept apart from the table classes)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from ..core.domain import DINNER_OBJECTS
from ..core.priors import NAMED_PRIORS
from ..core.puns import CRITERIA
from .page_schemas import ConsentFormIn

Id = Field(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")
ObjectName = Literal[DINNER_OBJECTS]  # type: ignore[valid-type]
StepKind = Literal["practice", "demonstration", "query", "test"]


class Strict(BaseModel):
    """Unknown fields are an error: a typo should not pass silently."""

    model_config = ConfigDict(extra="forbid", strict=True)


class StepGuard(Strict):
    """Where the client believes the session is; if given and stale, the answer is 409 with the current state."""

    task_index: int | None = Field(None, ge=0, le=100)
    step_kind: StepKind | None = None
    step_index: int | None = Field(None, ge=0, le=100)


class ConsentIn(Strict):
    agree: bool
    consent_version: str = Field(min_length=1, max_length=64)


class PlacementIn(StepGuard):
    object: ObjectName  # type: ignore[valid-type]


class AssessmentIn(StepGuard):
    acceptable: bool | None = Field(description="required for queries; optional for test executions")
    shown_fraction: float | None = Field(None, ge=0, le=1, description="how much of the robot's recorded motion "
                                         "the page played before the verdict (1: to the end; empty: unknown)")


class QuestionnaireIn(Strict):
    answers: dict[str, int | str | None] = Field(max_length=100)


class QuizIn(Strict):
    answers: dict[str, int] = Field(max_length=20, description="quiz item id -> number of the chosen option, from 0")


class JoinIn(Strict):
    prolific_pid: str | None = Field(None, min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")
    study_id: str | None = Field(None, min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")
    session_id: str | None = Field(None, min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")


class ParticipantState(BaseModel):
    """What a participant sees; every participant action answers with it."""

    participant_id: int
    token: str
    study_id: str
    stage: Literal["consent", "instructions", "quiz", "task", "questionnaire", "done", "withdrawn", "screened_out"]
    n_events: int
    objects: list[str]
    consent: dict[str, Any]
    task: dict[str, Any] | None
    step: dict[str, Any] | None
    demonstration: dict[str, Any] | None
    execution: dict[str, Any] | None
    questionnaire: list[dict[str, Any]] | None
    completion: dict[str, Any] | None = Field(
        description="at the end: code, redirect_url (the study's completion URL with the code), reason for leaving "
                    "early (declined_consent, withdrew, comprehension, timeout) and the debriefing")
    quiz: dict[str, Any] | None = Field(None, description="at the quiz stage: items, failed_attempts, attempts_left")
    progress: dict[str, Any] | None = Field(None, description="{done, total, minutes_left, seconds_left}: steps of "
                                            "the whole study and the calibrated time left")
    idle: dict[str, Any] | None = Field(None, description="with a study time-out: {timeout_seconds, idle_seconds} "
                                        "(the page asks \"are you still there?\" a minute before)")
    replayed: bool = Field(False, description="true when an Idempotency-Key repeated an earlier request")


class JoinOut(BaseModel):
    participant_id: int
    token: str
    created: bool
    state: ParticipantState


class TaskIn(Strict):
    key: Literal["task1", "task2", "custom", "none"]
    ground_truth: str | None = Field(None, max_length=2000)
    name: str | None = Field(None, max_length=200)
    instructions: str | None = Field(None, max_length=5000)


class ItemIn(Strict):
    id: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
    text: str = Field(max_length=2000)
    kind: Literal["likert5", "rating10", "text", "attention", "anchored5", "anchored7", "tlx21"]
    required: bool = True
    expected: int | None = Field(None, ge=1, le=5,
                                 description="attention checks (shown as a 1-5 agreement scale): the expected answer")
    anchors: list[str] | None = Field(None, min_length=2, max_length=2, description="anchored5, anchored7 and "
                                      "tlx21 items: the labels of the low and the high end")
    instrument: str | None = Field(None, max_length=32, description="a standard questionnaire's name "
                                   "(GET /api/v1/instruments): its items are scored in scores.csv")
    instrument_item: str | None = Field(None, max_length=64, description="the item's key in that questionnaire")


class QuizItemIn(Strict):
    id: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
    text: str = Field(min_length=1, max_length=2000)
    options: list[str] = Field(min_length=2, max_length=10)
    correct: int = Field(ge=0, le=9, description="index (from 0) of the correct option")



class StudyIn(Strict):
    name: str = Field("Untitled study", max_length=200)
    tasks: list[TaskIn] = Field(min_length=1, max_length=10)
    conditions: list[Literal["active", "random", "batch"]] = Field(["active"], min_length=1, max_length=3)
    assignment: Literal["random", "balanced"] = "balanced"
    n_practice: int = Field(1, ge=0, le=20)
    n_demonstrations: int = Field(2, ge=0, le=20)
    n_queries: int = Field(3, ge=0, le=20)
    n_tests: int = Field(3, ge=0, le=20)
    prior: Literal[tuple(NAMED_PRIORS)] = "chains-2020-sat"  # type: ignore[valid-type]
    criterion: Literal[CRITERIA] = "min-regret"  # type: ignore[valid-type]
    questionnaire: list[ItemIn] = Field(default_factory=list, max_length=100)
    consent_text: str | None = Field(None, max_length=20000)
    consent_version: str | None = Field(None, max_length=64)
    completion_url: str | None = Field(None, max_length=500, pattern=r"^https?://\S+$",
                                       description="redirect after completion; {code} is replaced")
    pilot: bool = False
    completion_code: str | None = Field(None, min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$",
                                        description="every participant who finishes is redirected with this code")
    screened_out_code: str | None = Field(None, min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$",
                                          description="for those who declined consent, failed a check or timed out")
    task_order: Literal["fixed", "random", "balanced"] = "fixed"
    quiz: list[QuizItemIn] = Field(default_factory=list, max_length=20)
    quiz_max_attempts: int = Field(2, ge=1, le=10)
    timeout_minutes: int | None = Field(None, ge=1, le=1440)
    robot_speed: float = Field(1.0, ge=1.0, le=3.0, description="the robot's motion is shown this many times faster "
                               "than real time (recordings keep real time)")
    # The participant page's settings (services/page_settings.py).
    consent_form: ConsentFormIn | None = None
    allow_anonymous: bool = Field(False, description="a study link without PROLIFIC_PID may join without an id "
                                  "(otherwise the page asks for the Prolific ID)")
    quiz_feedback: bool = Field(True, description="a failed comprehension quiz names the questions answered wrongly")


STUDY_FIELDS = tuple(StudyIn.model_fields)


class StudyOut(BaseModel):
    id: str
    name: str
    status: Literal["draft", "open", "closed"]
    pilot: bool
    tasks: list[dict[str, Any]]
    conditions: list[str]
    assignment: str
    n_practice: int
    n_demonstrations: int
    n_queries: int
    n_tests: int
    prior: str
    criterion: str
    questionnaire: list[dict[str, Any]]
    consent_text: str
    consent_version: str
    completion_url: str | None
    completion_code: str | None
    screened_out_code: str | None
    task_order: str
    quiz: list[dict[str, Any]]
    quiz_max_attempts: int
    timeout_minutes: int | None
    robot_speed: float = 1.0
    consent_form: dict[str, str] = Field(default_factory=dict)
    allow_anonymous: bool = False
    quiz_feedback: bool = True
    created_at: str | None
    updated_at: str | None


class ParticipantBaseOut(BaseModel):
    """What every experimenter view shows about a participant (services.monitoring.participant_row)."""

    participant_id: int
    condition: str
    stage: str
    task_index: int
    status: Literal["active", "idle", "done", "withdrawn", "screened_out"]
    pilot: bool
    end_reason: str | None = None
    attention_failed: bool = False
    task_order: list[int] | None = None
    elapsed_seconds: float | None = Field(None, description="from joining to finishing, or to now if under way")
    attention_signals: dict[str, int] = Field(default_factory=dict, description="the page's attention telemetry: "
                                              "tab_hidden, window_blur, paste counts")
    prolific_pid: str | None
    created_at: str | None
    last_activity_at: str | None
    finished_at: str | None
    n_events: int
    completion_code: str | None


class ParticipantRowOut(ParticipantBaseOut):
    phase: str | None


class BeliefOut(BaseModel):
    participant_id: int
    condition: str
    stage: str
    tasks: list[dict[str, Any]]


class FieldErrorOut(BaseModel):
    field: str = Field(description="the field's path, e.g. tasks.0.ground_truth")
    message: str


class ErrorOut(BaseModel):
    """Every error: what was wrong and what was expected; for participant conflicts, the current state."""

    detail: str
    state: ParticipantState | None = None
    errors: list[FieldErrorOut] | None = Field(None, description="422: every unacceptable field at once")


class StudyPatch(Strict):
    """Any fields of a study to change (the others keep their values)."""

    model_config = ConfigDict(extra="allow")


class PilotResetOut(BaseModel):
    study_id: str
    erased: list[int]


class ErasureOut(BaseModel):
    participant_id: int
    erased_by: str
    reason: Literal["erasure", "pilot_reset"]
    pilot: bool
    erased_at: str | None


class FormulaOut(BaseModel):
    formula: str
    description: str


ERROR_MEANINGS = {
    400: "the body could not be parsed",
    401: "missing or wrong token",
    404: "no such study, participant or export",
    409: "out of order, stale step, reused Idempotency-Key or study not open; includes the current state",
    413: "request body over 1 MiB",
    422: "malformed request or unacceptable values",
    429: "too many wrong experimenter tokens from this address; wait Retry-After seconds",
    503: "the database is busy or unavailable; try again after Retry-After seconds (nothing was lost)",
}


def error_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI entries for the error answers a router can give."""
    return {code: {"model": ErrorOut, "description": ERROR_MEANINGS[code]} for code in codes}
