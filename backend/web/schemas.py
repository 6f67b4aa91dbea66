"""Request and response models of the REST API (kept apart from the table classes)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from ..core.domain import DINNER_OBJECTS
from ..services.outcomes import OUTCOMES
# The study definition's model is the services' validator: one set of rules for the API and the services.
from ..services.study_definition import StudyIn as StudyIn

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
    progress: dict[str, Any] | None = Field(None, description="{done, total, minutes_left}: steps of the whole study")
    replayed: bool = Field(False, description="true when an Idempotency-Key repeated an earlier request")


class JoinOut(BaseModel):
    participant_id: int
    token: str
    created: bool
    state: ParticipantState




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
    declined_consent_code: str | None = None
    failed_quiz_code: str | None = None
    failed_attention_code: str | None = None
    timed_out_code: str | None = None
    withdrew_code: str | None = None
    screened_out_code: str | None
    task_order: str
    quiz: list[dict[str, Any]]
    quiz_max_attempts: int
    timeout_minutes: int | None
    robot_speed: float = 1.0
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
    prolific_pid: str | None
    created_at: str | None
    last_activity_at: str | None
    finished_at: str | None
    n_events: int
    completion_code: str | None = Field(description="the code the participant was shown at the end")
    outcome: Literal[OUTCOMES] | None = Field(  # type: ignore[valid-type]
        None, description="why they were given that code: how their study ended (empty while under way)")


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
