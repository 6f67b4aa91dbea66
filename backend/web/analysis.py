"""Experimenter analysis endpoints for the dashboard: live table, participant history, learning curves, replays."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query
from pydantic import BaseModel, Field

from ..core.counterfactual import spec_pattern
from ..services import analysis
from ..services import what_if as what_if_service
from .deps import ContextDep, Experimenter, ParticipantId, StepIndex
from .schemas import ClauseMarginalOut, ParticipantBaseOut, error_responses, learner_path_field

router = APIRouter(prefix="/api/v1/studies", tags=["analysis"], dependencies=[Experimenter],
                   responses=error_responses(401, 404, 422))

StepKind = Literal["practice", "demonstration", "query", "test"]


class StepOut(BaseModel):
    """Where a teaching session is (kind done when the task is over)."""

    kind: Literal["practice", "demonstration", "query", "test", "done"]
    index: int
    total: int


class LiveStepOut(StepOut):
    task_index: int


class TaskConsistencyOut(BaseModel):
    """One task's teacher consistency (docs/experiments.md, "Teacher consistency")."""

    task_index: int
    score: float | None = Field(description="mean probability the learner gave the participant's verdicts just "
                                "before each (queries and tests); null without verdicts")
    lowest: float | None = Field(description="the least probable verdict's probability")
    n_verdicts: int
    flagged: bool = Field(description="a verdict's probability was below flag_below")


class ConsistencyOut(BaseModel):
    """A participant's teacher consistency over the tasks they started."""

    score: float | None = Field(description="the lowest task score")
    flagged: bool = Field(description="some task is flagged: a reason to look at the session, not a verdict on "
                          "the participant")
    flag_below: float
    tasks: list[TaskConsistencyOut]


class LiveRowOut(ParticipantBaseOut):
    n_tasks: int
    step: LiveStepOut | None
    dropout: bool = Field(description="not finished and inactive longer than dropout_minutes")
    inactive_minutes: float
    consistency: ConsistencyOut


class LiveOut(BaseModel):
    study_id: str
    now: str
    dropout_minutes: float
    participants: list[LiveRowOut]


class RankedFormulaOut(BaseModel):
    """One of the learner's most probable formulas."""

    formula: str
    description: str
    p: float


class RecordOut(BaseModel):
    kind: StepKind
    acceptable: bool | None
    trace: list[list[str]]


class BeliefStepOut(BaseModel):
    """The belief after `step` learning records (0: the prior); similarity is null when the truth is unknown."""

    step: int
    record: RecordOut | None
    entropy: float
    similarity: float | None
    map_similarity: float | None
    map_formula: str
    map_description: str
    top: list[RankedFormulaOut]
    learner: Literal["enumerating", "exact"] = learner_path_field()
    map_p: float = Field(description="the MAP formula's probability under the learner's belief")
    marginals: list[ClauseMarginalOut] = Field(description="the clauses most probably in the formula, most "
                                               "probable first")


class ExecutionOut(BaseModel):
    """A practice trial or demonstration (by the participant), or a query or test (by the robot)."""

    task_index: int
    kind: StepKind
    index: int
    by: Literal["participant", "robot"]
    status: Literal["running", "finished", "assessed"]
    objects: list[str] | None
    trace: list[list[str]] | None
    acceptable: bool | None
    p_acceptable: float | None
    learning_step: int | None = Field(description="the belief step this execution produced, if the learner used it")
    started_at: str | None
    finished_at: str | None


class SessionConsistencyOut(BaseModel):
    """A task's verdicts' probabilities, each just before the verdict was given."""

    p_verdicts: list[float | None] = Field(description="per learning step (0: the prior): a query's verdict's "
                                           "probability, null for the prior and demonstrations")
    p_tests: list[float] = Field(description="per assessed test, in order (against the final belief)")
    n_verdicts: int
    score: float | None
    lowest: float | None
    flagged: bool
    flag_below: float


class TaskHistoryOut(BaseModel):
    task_index: int
    task: str
    name: str | None
    ground_truth: str | None
    ground_truth_description: str | None
    step: StepOut
    steps: list[BeliefStepOut]
    executions: list[ExecutionOut]
    consistency: SessionConsistencyOut


class EventOut(BaseModel):
    seq: int
    created_at: str | None
    kind: str
    task_index: int | None
    step_kind: str | None
    step_index: int | None
    payload: dict[str, Any]


class AnswerOut(BaseModel):
    item_id: str
    text: str | None
    kind: str | None
    answer: int | str | None


class ParticipantInfoOut(ParticipantBaseOut):
    seed: int


class HistoryOut(BaseModel):
    study_id: str
    participant: ParticipantInfoOut
    tasks: list[TaskHistoryOut]
    events: list[EventOut]
    questionnaire: list[AnswerOut]


class CurvePointOut(BaseModel):
    step: int
    n: int = Field(description="participants whose belief reached this step")
    mean_entropy: float
    n_similarity: int
    median_similarity: float | None
    q1_similarity: float | None
    q3_similarity: float | None


class ConditionCurveOut(BaseModel):
    condition: str
    points: list[CurvePointOut]


class ParticipantCurveOut(BaseModel):
    participant_id: int
    condition: str
    finished: bool
    entropy: list[float]
    similarity: list[float | None]


class TaskCurvesOut(BaseModel):
    task_index: int
    task: str
    name: str | None
    has_ground_truth: bool
    all: list[CurvePointOut]
    conditions: list[ConditionCurveOut]
    participants: list[ParticipantCurveOut]


class CurvesOut(BaseModel):
    study_id: str
    finished_only: bool
    include_pilot: bool
    tasks: list[TaskCurvesOut]


@router.get("/{study_id}/live", response_model=LiveOut)
def live(study_id: str, ctx: ContextDep,
         dropout_minutes: Annotated[float | None, Query(gt=0, le=100_000, description=(
             "flag unfinished participants inactive longer than this; default: the server's active_minutes"))] = None,
         ) -> dict[str, Any]:
    """Participants with their current step, live status and a dropout flag."""
    return analysis.live_participants(ctx, study_id, dropout_minutes=dropout_minutes)


@router.get("/{study_id}/participants/{participant_id}/history", response_model=HistoryOut)
def history(study_id: str, participant_id: ParticipantId, ctx: ContextDep) -> dict[str, Any]:
    """Every event, every execution with its trace and verdict, and the belief after each learning step."""
    return analysis.participant_history(ctx, study_id, participant_id)


@router.get("/{study_id}/curves", response_model=CurvesOut)
def curves(study_id: str, ctx: ContextDep,
           finished_only: Annotated[bool, Query(description="only participants who completed the study")] = False,
           include_pilot: Annotated[bool, Query(description="also pilot participants")] = False,
           ) -> dict[str, Any]:
    """Learning curves per task and condition: median similarity and mean entropy after each learning step."""
    return analysis.learning_curves(ctx, study_id, finished_only=finished_only, include_pilot=include_pilot)


class WhatIfStepOut(BaseModel):
    """A learner's belief after `step` learning records (0: the prior)."""

    step: int
    similarity: float | None
    entropy: float
    map_formula: str


class WhatIfLearnerOut(BaseModel):
    learner: str = Field(description="the spec as given; 'study' is the study's own learner")
    prior: str
    flip_rate: float = Field(description="0: the authors' learner; above: the noise-aware one")
    data: Literal["all", "demonstrations"]
    steps: list[WhatIfStepOut] = Field(description="empty when the learner is unavailable for this task")
    unavailable: str | None = Field(description="why this learner cannot run on this task (past five objects the "
                                    "exact learner has no noise-aware likelihood yet); null when it ran")


class WhatIfTaskOut(BaseModel):
    task_index: int
    task: str
    name: str | None
    has_ground_truth: bool
    records: list[Literal["demonstration", "query"] | None] = Field(description="per step, what was learned from")
    learners: list[WhatIfLearnerOut]


class WhatIfOut(BaseModel):
    study_id: str
    participant_id: int
    study_prior: str
    study_flip_rate: float
    tasks: list[WhatIfTaskOut]


# What the service accepts, for the schema (the service checks it, so a refusal names the spec and what it expects).
LEARNERS_SCHEMA: dict[str, Any] = {"items": {"type": "string", "pattern": spec_pattern()},
                                   "maxItems": what_if_service.MAX_LEARNERS, "uniqueItems": True}


@router.get("/{study_id}/participants/{participant_id}/what-if", response_model=WhatIfOut)
def what_if(study_id: str, participant_id: ParticipantId, ctx: ContextDep,
            learner: Annotated[list[str] | None, Query(json_schema_extra=LEARNERS_SCHEMA, description=(
                "a learner to replay the participant's data through (repeatable, at most 6): settings prior=NAME, "
                "flip=P (noise-aware, P in [0, 0.5); flip=0 the authors'), data=all|demonstrations, "
                "comma-separated; unset ones are the study's. Default: flip=0.1 and data=demonstrations"))] = None,
            ) -> dict[str, Any]:
    """What the participant's recorded demonstrations and verdicts teach other learners, step by step, beside the
    study's own learner (read only; the dashboard's view of ``tableteach replay``)."""
    return what_if_service.what_if(ctx, study_id, participant_id, learner or [])


class TableOut(BaseModel):
    name: str
    x: float
    y: float
    half_x: float
    half_y: float


class PoseOut(BaseModel):
    x: float
    y: float
    yaw: float = Field(description="radians about +z")


class ObjectLayoutOut(BaseModel):
    shape: Literal["disc", "bar"]
    half_x: float
    half_y: float
    start: PoseOut
    slot: PoseOut


class LayoutOut(BaseModel):
    """The scene from above, in metres in the world frame."""

    tables: list[TableOut]
    robot: dict[str, float]
    objects: dict[str, ObjectLayoutOut]


class RecordingOut(BaseModel):
    bodies: list[str]
    times: list[float]
    poses: list[list[list[float]]] = Field(description="per frame, per body: x, y, z, qw, qx, qy, qz")
    action_ends: list[float]


class ReplayOut(BaseModel):
    task_index: int
    kind: StepKind
    index: int
    source: Literal["recording", "trace"]
    objects: list[str]
    trace: list[list[str]]
    acceptable: bool | None
    layout: LayoutOut
    recording: RecordingOut | None


@router.get("/{study_id}/participants/{participant_id}/replays/{task_index}/{step_kind}/{step_index}",
            response_model=ReplayOut)
def replay(study_id: str, participant_id: ParticipantId, task_index: StepIndex, step_kind: StepKind,
           step_index: StepIndex, ctx: ContextDep) -> dict[str, Any]:
    """A step's replay: the robot's recorded poses when saved (MuJoCo robot), else its trace (indices from 0)."""
    return analysis.replay(ctx, study_id, participant_id, task_index=task_index, step_kind=step_kind,
                           step_index=step_index)
