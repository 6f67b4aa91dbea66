"""Experimenter endpoints: studies, participants' live status and beliefs (auth: the experimenter token)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Query, Response, status
from .. import services
from ..services.study_definition import ANY_OBJECTS_FORMULA_PATTERN
from ..errors import InvalidInput
from .deps import ActorDep, ContextDep, Experimenter, ParticipantId
from .schemas import (BeliefOut, ErasureOut, FormulaDescriptionOut, ParticipantBaseOut, ParticipantRowOut,
                      PilotResetOut, StatisticsOut, StudyIn, StudyOut, error_responses)

ERRORS = error_responses(400, 401, 404, 409, 422)
router = APIRouter(prefix="/api/v1/studies", tags=["experimenter"], dependencies=[Experimenter], responses=ERRORS)
formulas = APIRouter(prefix="/api/v1/formulas", tags=["experimenter"], dependencies=[Experimenter],
                     responses=error_responses(401, 422))
StudyBody = Annotated[dict[str, Any], Body(description="a study definition: the fields of StudyIn (docs/server.md)")]
STUDY_IN = {"requestBody": {"required": True, "content": {"application/json": {
    "schema": {"$ref": "#/components/schemas/StudyIn"}}}}}


@router.get("", response_model=list[StudyOut])
def list_studies(ctx: ContextDep, include_archived: Annotated[bool, Query(
        description="also the archived studies")] = False) -> list[dict]:
    """Every study, newest first (archived ones only if asked for)."""
    return services.list_studies(ctx, include_archived=include_archived)


@router.post("", response_model=StudyOut, status_code=status.HTTP_201_CREATED, openapi_extra=STUDY_IN)
def create_study(body: StudyBody, ctx: ContextDep) -> dict:
    """Create a study (status draft; open it to let participants join). A 422 lists every bad field in errors."""
    return services.create_study(ctx, body)


@router.get("/{study_id}", response_model=StudyOut)
def get_study(study_id: str, ctx: ContextDep) -> dict:
    """One study."""
    return services.get_study(ctx, study_id)


@router.get("/{study_id}/spec", response_model=StudyIn)
def study_spec(study_id: str, ctx: ContextDep) -> dict:
    """The study as the definition that would create it again (what the dashboard's edit form starts from)."""
    return services.editable_spec(services.get_study(ctx, study_id))


@router.patch("/{study_id}", response_model=StudyOut)
def update_study(study_id: str, body: StudyBody, ctx: ContextDep) -> dict:
    """Change any fields of a draft study (the others keep their values); an open or closed study only its name,
    pilot flag, completion codes, completion URL and timeout (409 for the rest: clone it instead)."""
    return services.update_study(ctx, study_id, body)


@router.delete("/{study_id}", status_code=status.HTTP_204_NO_CONTENT, response_class=Response)
def delete_study(study_id: str, ctx: ContextDep) -> Response:
    """Delete a study without participants (409 if it has any: archive it instead, nothing is lost)."""
    services.delete_study(ctx, study_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/{study_id}/archive", response_model=StudyOut)
def archive_study(study_id: str, ctx: ContextDep) -> dict:
    """Hide the study from the list (an open one is closed first); its data stay."""
    return services.archive_study(ctx, study_id)


@router.post("/{study_id}/unarchive", response_model=StudyOut)
def unarchive_study(study_id: str, ctx: ContextDep) -> dict:
    """Show an archived study in the list again (it stays closed)."""
    return services.archive_study(ctx, study_id, archived=False)


@router.get("/{study_id}/statistics", response_model=StatisticsOut)
def statistics(study_id: str, ctx: ContextDep, include_pilot: Annotated[bool, Query(
        description="also pilot participants")] = False) -> dict:
    """Funnel by stage, completion-time distribution and condition x task-order counts."""
    return services.study_statistics(ctx, study_id, include_pilot=include_pilot)


@router.post("/{study_id}/clone", response_model=StudyOut, status_code=status.HTTP_201_CREATED)
def clone_study(study_id: str, ctx: ContextDep) -> dict:
    """A draft copy of the study under a new id (its participants are not copied)."""
    return services.clone_study(ctx, study_id)


@router.post("/{study_id}/open", response_model=StudyOut)
def open_study(study_id: str, ctx: ContextDep) -> dict:
    """Let participants join."""
    return services.open_study(ctx, study_id)


@router.post("/{study_id}/close", response_model=StudyOut)
def close_study(study_id: str, ctx: ContextDep) -> dict:
    """Stop new participants from joining; those under way may finish."""
    return services.close_study(ctx, study_id)


@router.post("/{study_id}/pilot/reset", response_model=PilotResetOut)
def reset_pilot(study_id: str, ctx: ContextDep, actor: ActorDep) -> dict:
    """Erase every pilot participant of the study (each gets an audit entry); nobody else is touched."""
    return services.reset_pilot(ctx, study_id, by=actor.name)


@router.get("/{study_id}/participants", response_model=list[ParticipantRowOut])
def list_participants(study_id: str, ctx: ContextDep) -> list[dict]:
    """Participants with stage, live status (active, idle, done, withdrawn, screened_out) and last activity."""
    return services.list_participants(ctx, study_id)


@router.delete("/{study_id}/participants/{participant_id}", status_code=status.HTTP_204_NO_CONTENT,
               response_class=Response)
def erase_participant(study_id: str, participant_id: ParticipantId, ctx: ContextDep,
                      actor: ActorDep) -> Response:
    """Erase one participant's events, answers, beliefs and robot recordings; an audit entry (no personal data)
    is kept. Erasing again answers 204 too."""
    services.erase_participant(ctx, study_id, participant_id, by=actor.name)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/{study_id}/participants/{participant_id}/restore", response_model=ParticipantBaseOut)
def restore_participant(study_id: str, participant_id: ParticipantId, ctx: ContextDep, actor: ActorDep) -> dict:
    """Bring back a participant who timed out (where they were), failed the quiz (fresh attempts) or declined
    consent; logged as a "restored" event. 409 for anyone else."""
    return services.restore_participant(ctx, study_id, participant_id, by=actor.name)


@router.post("/{study_id}/participants/{participant_id}/help", response_model=ParticipantBaseOut)
def help_participant(study_id: str, participant_id: ParticipantId, ctx: ContextDep, actor: ActorDep) -> dict:
    """Move a stuck participant past their stage (instructions, quiz, the current task, questionnaire); logged
    as a "helped_on" event. 409 at consent or after the end."""
    return services.help_on(ctx, study_id, participant_id, by=actor.name)


@router.get("/{study_id}/erasures", response_model=list[ErasureOut])
def erasures(study_id: str, ctx: ContextDep) -> list[dict]:
    """The study's erasure audit log: which participant number, who, when, why."""
    return services.erasure_log(ctx, study_id)


@router.get("/{study_id}/participants/{participant_id}/belief", response_model=BeliefOut)
def belief(study_id: str, participant_id: ParticipantId, ctx: ContextDep) -> dict:
    """Per task: the learner's top formulas in plain English, entropy, similarity to the ground truth."""
    return services.belief_summary(ctx, study_id, participant_id)


OBJECT_LIST_PATTERN = r"^[a-z][a-z0-9_]{0,31}(,[a-z][a-z0-9_]{0,31}){1,9}$"


@formulas.get("/describe", response_model=FormulaDescriptionOut)
def describe_formula(formula: Annotated[str, Query(min_length=1, max_length=2000,
                                                   pattern=ANY_OBJECTS_FORMULA_PATTERN,
                                                   description="e.g. F(bowl) & (!fork U knife)")],
                     objects: Annotated[str | None, Query(max_length=400, pattern=OBJECT_LIST_PATTERN, description=(
                         "a study's own objects, comma-separated (empty: the dinner table's)"))] = None) -> dict:
    """A custom task's ground-truth formula in canonical form and in plain words (422 says what is wrong)."""
    names = None if not objects else objects.split(",")
    if names is not None and len(set(names)) != len(names):
        raise InvalidInput(f"objects: {objects!r} names an object twice; expected distinct names")
    return services.describe_formula(formula, names)
