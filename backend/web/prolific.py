"""Reconciliation with Prolific (auth: the experimenter token): upload its submissions export, compare its
statuses with ours, set a bonus rule and download the bulk-bonus file."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Request
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from ..errors import InvalidFields
from ..services import prolific
from ..services.outcomes import OUTCOMES
from .deps import ContextDep, Experimenter
from .schemas import error_responses

router = APIRouter(prefix="/api/v1/studies", tags=["prolific"], dependencies=[Experimenter],
                   responses=error_responses(400, 401, 404, 422))
CSV_BODY = {"requestBody": {"required": True, "content": {"text/csv": {
    "schema": {"type": "string"}, "example": "Submission id,Participant id,Status,Completion code\n"
    "64f1a2,5f8e3c1d2a,APPROVED,C1DONE\n64f1a3,5f8e3c1d2b,RETURNED,\n"}}}}


class UploadOut(BaseModel):
    study_id: str
    n_submissions: int
    uploaded_at: str | None


class ReconciliationRowOut(BaseModel):
    prolific_pid: str
    prolific_status: str | None = Field(description="Prolific's status (empty: not in the uploaded export)")
    entered_code: str | None = Field(description="the code entered on Prolific")
    submission_id: str | None
    participant_id: int | None = Field(description="our participant (empty: this id never joined here)")
    stage: str | None
    outcome: Literal[OUTCOMES] | None  # type: ignore[valid-type]
    completion_code: str | None = Field(description="the code we showed")
    mismatch: str | None = Field(description="why Prolific's status and ours disagree, in words (empty: they agree)")


class ReconciliationOut(BaseModel):
    study_id: str
    uploaded_at: str | None
    n_mismatches: int
    rows: list[ReconciliationRowOut]


Amount = Field(None, ge=0, le=float(prolific.MAX_BONUS), description="in the study's Prolific currency, e.g. 1.5")


class BonusAmountsIn(BaseModel):
    """An amount per outcome (services/outcomes.py); outcomes left out get no bonus."""

    model_config = ConfigDict(extra="forbid")
    completed: float | None = Amount
    declined_consent: float | None = Amount
    comprehension: float | None = Amount
    attention: float | None = Amount
    timeout: float | None = Amount
    withdrew: float | None = Amount


class BonusRuleIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    amounts: BonusAmountsIn


class BonusRuleOut(BaseModel):
    study_id: str
    amounts: dict[str, str]


@router.put("/{study_id}/prolific/submissions", response_model=UploadOut, openapi_extra=CSV_BODY,
            operation_id="upload_prolific_submissions")
async def upload_submissions(study_id: str, request: Request, ctx: ContextDep) -> dict[str, Any]:
    """Upload Prolific's submissions export (CSV, as downloaded from the study's submissions page); it replaces
    the earlier upload. A 422 names the row and column of every bad cell."""
    raw = await request.body()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InvalidFields([{"field": "file", "message": "is not UTF-8 text; expected Prolific's CSV export"}]) \
            from exc
    return await run_in_threadpool(prolific.upload_submissions, ctx, study_id, text)


@router.get("/{study_id}/prolific/reconciliation", response_model=ReconciliationOut,
            operation_id="prolific_reconciliation")
def reconciliation(study_id: str, ctx: ContextDep) -> dict[str, Any]:
    """Per Prolific id: Prolific's status against ours, with mismatches (returned but finished here, approved but
    screened out, unknown ids, a different code)."""
    return prolific.reconciliation(ctx, study_id)


@router.put("/{study_id}/prolific/bonus-rule", response_model=BonusRuleOut, operation_id="set_bonus_rule")
def set_bonus_rule(study_id: str, body: BonusRuleIn, ctx: ContextDep) -> dict[str, Any]:
    """The study's bonus rule: an amount per outcome."""
    return prolific.set_bonus_rule(ctx, study_id, body.amounts.model_dump(exclude_none=True))


@router.get("/{study_id}/prolific/bonus-rule", response_model=BonusRuleOut, operation_id="get_bonus_rule")
def get_bonus_rule(study_id: str, ctx: ContextDep) -> dict[str, Any]:
    """The study's bonus rule."""
    return prolific.bonus_rule(ctx, study_id)


@router.get("/{study_id}/prolific/bonuses.csv", response_class=Response, operation_id="bonus_file",
            responses={200: {"content": {"text/csv": {"schema": {"type": "string", "format": "binary"}}},
                             "description": "Prolific's bulk-bonus format: one line 'participant id,amount' each"}})
def bonus_file(study_id: str, ctx: ContextDep) -> Response:
    """The bonus file to paste into Prolific's bulk bonus (or send with its API), from the study's rule."""
    lines = prolific.bonus_lines(ctx, study_id)
    return Response("".join(f"{pid},{amount}\n" for pid, amount in lines), media_type="text/csv; charset=utf-8",
                    headers={"Content-Disposition": f'attachment; filename="{study_id}-bonuses.csv"'})
