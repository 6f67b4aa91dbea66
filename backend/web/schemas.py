"""Request and response models of the REST API (kept apart from the table classes)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from ..scenes.spec import NAME_PATTERN
from ..services.outcomes import OUTCOMES
# The study definition's model is the services' validator: one set of rules for the API and the services.
from ..services.study_definition import StudyIn as StudyIn
from ..services.study_definition import integral

Id = Field(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$")
# An object of the participant's study: the dinner objects (dinner_plate, small_plate, bowl, knife, fork) or its own.
ObjectName = Annotated[str, Field(min_length=1, max_length=32, pattern=NAME_PATTERN,
                                  description="one of the objects the state lists (`objects`)")]
StepKind = Literal["practice", "demonstration", "query", "test"]


class Strict(BaseModel):
    """Unknown fields are an error: a typo should not pass silently; 18.0 is the whole number 18."""

    model_config = ConfigDict(extra="forbid", strict=True)

    @field_validator("*", mode="before")
    @classmethod
    def _whole_numbers(cls, value: Any) -> Any:
        return integral(value)


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


class ConsentSectionOut(BaseModel):
    """One section of the structured consent form."""

    key: str
    heading: str
    text: str


class ConsentOut(BaseModel):
    text: str = Field(description="the consent text to show")
    version: str = Field(description="send it back with the answer (POST /me/consent)")
    given_at: str | None = Field(description="when consent was given (ISO 8601), empty before")
    sections: list[ConsentSectionOut] = Field(default_factory=list, description="the structured consent form")
    allow_anonymous: bool = Field(False, description="the study lets participants join without a Prolific ID")
    anonymous: bool = Field(False, description="this participant joined without a Prolific ID")


class IdleOut(BaseModel):
    """How long the participant has been idle, against the study's time-out."""

    timeout_seconds: int
    idle_seconds: float


class StateTaskOut(BaseModel):
    """The task under way."""

    index: int = Field(description="the task's number in the study definition, from 0")
    total: int = Field(description="how many tasks the study has")
    name: str
    instructions: str
    key: Literal["task1", "task2", "custom", "none"]
    position: int = Field(description="the task's place in this participant's order, from 0")
    required: list[str] = Field(description="objects the task says must end up on the table")
    goal_picture: str | None = Field(None, description="a study with its own objects: the path of the task's goal "
                                     "picture (SVG); empty for the dinner table's tasks")


class StateStepOut(BaseModel):
    """Where the participant is within the task."""

    kind: Literal["practice", "demonstration", "query", "test", "done"]
    index: int = Field(description="the step's number within its kind, from 0")
    total: int = Field(description="how many steps of this kind the task has")


class DemonstrationOut(BaseModel):
    """A practice trial or demonstration under way: what the participant has placed and the robot reported."""

    placed: list[str] = Field(description="objects placed so far, in order")
    labels: list[str] = Field(description="objects in their places on the table now, as the robot reported them")
    trace: list[list[str]] = Field(description="the table after each placement")
    settled: bool = Field(description="the robot has reported the table after every placement")


class ExecutionStateOut(BaseModel):
    """The robot's execution of the current query or test."""

    kind: Literal["query", "test"]
    index: int
    status: Literal["not_started", "running", "finished"]
    events: list[str] | None = Field(description="the objects the robot places, in order (once started)")
    trace: list[list[str]] | None = Field(description="the table after each of the robot's placements (finished)")
    replays: int = Field(0, description="how often the participant has watched it again")
    motion_seconds: float = Field(0.0, description="how long the recorded motion plays (0 before it is worked out)")


class QuestionnaireItemOut(BaseModel):
    """A questionnaire item as the participant sees it (an attention check looks like any agreement item)."""

    id: str
    text: str
    kind: Literal["likert5", "rating10", "text", "attention", "anchored5", "anchored7", "tlx21"]
    required: bool
    anchors: list[str] | None = Field(None, description="anchored scales: the low and high labels")


class LearnedOut(BaseModel):
    """The debriefing: what the robot believes a task is, once the participant has finished."""

    task_index: int
    map_formula: str
    map_description: str
    summary: str


class CompletionOut(BaseModel):
    """How the participant's study ended and the code they are shown for it."""

    code: str | None = Field(description="the completion code for this outcome (empty: the study set none)")
    reason: Literal["declined_consent", "withdrew", "comprehension", "timeout"] | None = Field(
        description="why the participant left early; empty for those who finished")
    redirect_url: str | None = Field(description="the study's completion URL with the code; empty if it has none")
    learned: list[LearnedOut]
    return_url: str | None = Field(None, description="after withdrawing: where the participant goes back to")


class QuizQuestionOut(BaseModel):
    id: str
    text: str
    options: list[str]


class QuizStateOut(BaseModel):
    items: list[QuizQuestionOut]
    failed_attempts: int
    attempts_left: int
    answers: dict[str, int] = Field(default_factory=dict, description="the last attempt's answers, kept")
    wrong: list[str] | None = Field(None, description="the questions the last attempt answered wrongly (empty: "
                                    "none yet, or the study hides it)")


class ProgressOut(BaseModel):
    done: int = Field(description="steps of the whole study done")
    total: int = Field(description="steps of the whole study")
    minutes_left: int = Field(description="about how many minutes are left (rounded up)")
    seconds_left: float | None = Field(None, description="the calibrated estimate of the time left, in seconds")


class OwnObjectOut(BaseModel):
    """One of the study's own objects as the page shows it."""

    name: str
    shape: str
    colour: str = Field(description="#rrggbb")


class ParticipantState(BaseModel):
    """What a participant sees; every participant action answers with it."""

    participant_id: int
    token: str
    study_id: str
    stage: Literal["consent", "instructions", "quiz", "task", "questionnaire", "done", "withdrawn", "screened_out"]
    n_events: int
    objects: list[str]
    own_objects: list[OwnObjectOut] | None = Field(None, description="a study with its own objects: each one's shape "
                                                   "and colour (empty: the dinner table)")
    consent: ConsentOut
    task: StateTaskOut | None = Field(description="at the task stage")
    step: StateStepOut | None = Field(description="at the task stage")
    demonstration: DemonstrationOut | None = Field(description="during a practice trial or demonstration")
    execution: ExecutionStateOut | None = Field(description="during a query or test")
    questionnaire: list[QuestionnaireItemOut] | None = Field(description="at the questionnaire stage")
    completion: CompletionOut | None = Field(description="at the end, or after leaving early")
    quiz: QuizStateOut | None = Field(None, description="at the quiz stage")
    progress: ProgressOut | None = Field(None, description="steps of the whole study")
    idle: IdleOut | None = Field(None, description="with a study time-out: how long the participant has been idle "
                                 "(the page asks \"are you still there?\" a minute before the time-out)")
    replayed: bool = Field(False, description="true when an Idempotency-Key repeated an earlier request")
    etag: str = Field(description="this state's entity tag, as GET /api/v1/me sends it in its ETag header and each "
                                  "change event in its `state`: a page that holds it has nothing new to read")


class JoinOut(BaseModel):
    participant_id: int
    token: str
    created: bool
    state: ParticipantState




class StudySlotOut(BaseModel):
    x: float = Field(description="centimetres right of Table B's centre")
    y: float = Field(description="centimetres from Table B's centre towards the robot")


class StudyObjectOut(BaseModel):
    """One of a study's own objects."""

    name: str
    shape: str
    colour: str
    size: float = Field(description="centimetres: diameter, length or side by shape")
    slot: StudySlotOut


class StudyTaskOut(BaseModel):
    """A stored task: named tasks carry their fixed formula, custom ones their canonical formula."""

    key: Literal["task1", "task2", "custom", "none"]
    ground_truth: str | None
    name: str
    instructions: str


class StudyItemOut(BaseModel):
    id: str
    text: str
    kind: Literal["likert5", "rating10", "text", "attention", "anchored5", "anchored7", "tlx21"]
    required: bool
    expected: int | None = Field(None, description="attention checks: the expected answer (1-5)")
    anchors: list[str] | None = Field(None, description="anchored scales: the low and high labels")
    instrument: str | None = Field(None, description="the standard questionnaire the item is from")
    instrument_item: str | None = Field(None, description="the item's key in that questionnaire")


class StudyQuizItemOut(BaseModel):
    id: str
    text: str
    options: list[str]
    correct: int


class StudyOut(BaseModel):
    id: str
    name: str
    status: Literal["draft", "open", "closed"]
    pilot: bool
    tasks: list[StudyTaskOut]
    conditions: list[str]
    assignment: str
    n_practice: int
    n_demonstrations: int
    n_queries: int
    n_tests: int
    prior: str
    criterion: str
    questionnaire: list[StudyItemOut]
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
    quiz: list[StudyQuizItemOut]
    quiz_max_attempts: int
    timeout_minutes: int | None
    robot_speed: float = 1.0
    flip_rate: float = Field(0.0, description="the learner's assumed verdict-flip probability (0: the authors' "
                             "learner)")
    places: int | None = None
    archived_at: str | None = Field(None, description="when the study was archived (hidden from the list)")
    consent_form: dict[str, str] = Field(default_factory=dict)
    allow_anonymous: bool = False
    quiz_feedback: bool = True
    objects: list[StudyObjectOut] | None = Field(None, description="the study's own objects (empty: the dinner table)")
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
    completion_code: str | None = Field(description="the code the participant was shown at the end")
    outcome: Literal[OUTCOMES] | None = Field(  # type: ignore[valid-type]
        None, description="why they were given that code: how their study ended (empty while under way)")


class ParticipantRowOut(ParticipantBaseOut):
    phase: str | None


class BeliefOut(BaseModel):
    participant_id: int
    condition: str
    stage: str
    tasks: list[BeliefTaskOut]


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


class FunnelStageOut(BaseModel):
    stage: Literal["joined", "consented", "started", "finished_tasks", "completed"]
    label: str
    n: int = Field(description="participants who got at least this far")


class CompletionTimesOut(BaseModel):
    n: int
    values: list[float] = Field(description="seconds from joining to completing, sorted")
    median: float | None
    quartiles: list[float] | None = Field(description="25th, 50th and 75th percentiles (two or more values)")
    min: float | None
    max: float | None


class CellOut(BaseModel):
    condition: str
    task_order: list[int]
    tasks: list[str] = Field(description="the tasks' names in that order")
    n: int


class StatisticsOut(BaseModel):
    """How far participants got, how long finishing took, and the counterbalancing cells."""

    study_id: str
    n_participants: int
    include_pilot: bool
    funnel: list[FunnelStageOut]
    outcomes: dict[str, int] = Field(description="participants per outcome (completed, declined_consent, ...)")
    completion_seconds: CompletionTimesOut
    cells: list[CellOut] = Field(description="participants per condition x task order (withdrawn left out)")


class PilotResetOut(BaseModel):
    study_id: str
    erased: list[int]


class ErasureOut(BaseModel):
    participant_id: int
    erased_by: str
    reason: Literal["erasure", "pilot_reset"]
    pilot: bool
    erased_at: str | None


class FormulaDescriptionOut(BaseModel):
    """A formula in canonical form and in plain words."""

    formula: str = Field(description="canonical form, e.g. (!fork U knife) & F(bowl)")
    description: str = Field(description="in plain English")


class BeliefFormulaOut(BaseModel):
    formula: str
    description: str
    p: float = Field(description="its probability under the learner's belief")


class ClauseMarginalOut(BaseModel):
    clause: str = Field(description="a template clause, e.g. (!bowl U dinner_plate)")
    p: float = Field(description="the probability that the task's formula contains it, under the learner's belief")


def learner_path_field() -> Any:
    """The field saying which learner answered a belief view (the same words wherever one is shown)."""
    return Field(description="which learner answered: 'enumerating' (up to five objects: every formula listed, "
                 "'top' the most probable ones) or 'exact' (past five: no formula listed, 'top' holds the MAP "
                 "formula alone with its exact probability; 'marginals' say which clauses are likely)")


class BeliefTaskOut(BaseModel):
    """What the learner believes one task is."""

    task_index: int
    task: str
    phase: str = Field(description="the task's teaching phase (practice, demonstration, query, test, done)")
    n_observations: int = Field(description="demonstrations and assessed executions learned from")
    entropy: float = Field(description="entropy of the belief (nats)")
    similarity: float | None = Field(description="expected similarity to the ground truth (empty when unknown)")
    map_similarity: float | None
    map_formula: str
    map_description: str
    top: list[BeliefFormulaOut]
    learner: Literal["enumerating", "exact"] = learner_path_field()
    map_p: float = Field(description="the MAP formula's probability under the learner's belief")
    marginals: list[ClauseMarginalOut] = Field(description="the clauses most probably in the formula, most "
                                               "probable first")


ERROR_MEANINGS = {
    400: "the body could not be parsed",
    401: "missing or wrong token",
    403: "the token's role may not do this (analyst: read and export only; experimenter: not the accounts)",
    404: "no such study, participant or export",
    409: "out of order, stale step, reused Idempotency-Key, study not open or full; includes the current state",
    413: "request body over 1 MiB",
    422: "malformed request or unacceptable values",
    429: "too many wrong experimenter tokens, or joins, from this address; wait Retry-After seconds",
    503: "the database is busy or unavailable; try again after Retry-After seconds (nothing was lost)",
}


def error_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI entries for the error answers a router can give."""
    return {code: {"model": ErrorOut, "description": ERROR_MEANINGS[code]} for code in codes}
