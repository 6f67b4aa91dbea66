"""Experimenter endpoints: studies, participants' live status and beliefs (auth: the experimenter token)."""

from __future__ import annotations

from fastapi import APIRouter, status

from .. import services
from .deps import ContextDep, Experimenter, ParticipantId
from .schemas import BeliefOut, ParticipantRowOut, StudyIn, StudyOut, error_responses

ERRORS = error_responses(400, 401, 404, 409, 422)
router = APIRouter(prefix="/api/v1/studies", tags=["experimenter"], dependencies=[Experimenter], responses=ERRORS)


@router.get("", response_model=list[StudyOut])
def list_studies(ctx: ContextDep) -> list[dict]:
    """Every study, newest first."""
    return services.list_studies(ctx)


@router.post("", response_model=StudyOut, status_code=status.HTTP_201_CREATED)
def create_study(body: StudyIn, ctx: ContextDep) -> dict:
    """Create a study (status draft; open it to let participants join)."""
    return services.create_study(ctx, body.model_dump())


@router.get("/{study_id}", response_model=StudyOut)
def get_study(study_id: str, ctx: ContextDep) -> dict:
    """One study."""
    return services.get_study(ctx, study_id)


@router.post("/{study_id}/open", response_model=StudyOut)
def open_study(study_id: str, ctx: ContextDep) -> dict:
    """Let participants join."""
    return services.open_study(ctx, study_id)


@router.post("/{study_id}/close", response_model=StudyOut)
def close_study(study_id: str, ctx: ContextDep) -> dict:
    """Stop new participants from joining; those under way may finish."""
    return services.close_study(ctx, study_id)


@router.get("/{study_id}/participants", response_model=list[ParticipantRowOut])
def list_participants(study_id: str, ctx: ContextDep) -> list[dict]:
    """Participants with stage, live status (active, idle, done, withdrawn) and last activity."""
    return services.list_participants(ctx, study_id)


@router.get("/{study_id}/participants/{participant_id}/belief", response_model=BeliefOut)
def belief(study_id: str, participant_id: ParticipantId, ctx: ContextDep) -> dict:
    """Per task: the learner's top formulas in plain English, entropy, similarity to the ground truth."""
    return services.belief_summary(ctx, study_id, participant_id)
