"""Participant endpoints: one set for the browser page and scripted teachers (auth: the participant's token)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Request, Response, status
from starlette.concurrency import run_in_threadpool

from .. import services
from ..services import attention
from .browser import browser_secret, remember_browser
from .conditional import NOT_MODIFIED, client_has, not_modified, tag_answer
from .deps import ContextDep, IdempotencyKey, JoinAllowed, TokenDep
from .page_schemas import SignalIn
from .schemas import (AssessmentIn, ConsentIn, JoinIn, JoinOut, ParticipantState, PlacementIn,
                      QuestionnaireIn, QuizIn, StepGuard, error_responses)

ERRORS = error_responses(400, 401, 409, 422)
# The endpoints are async and hand only the services call to the thread pool: a plain `def` endpoint costs
# a second hop for FastAPI's response validation (and one per sync dependency), measured at about a fifth
# of the server's CPU per request (benchmarks/bench_server.py, docs/server.md).
router = APIRouter(prefix="/api/v1", tags=["participant"], responses=ERRORS)


def _expect(guard: StepGuard | None) -> services.Expect:
    if guard is None:
        return services.Expect()
    return services.Expect(guard.task_index, guard.step_kind, guard.step_index)


@router.post("/studies/{study_id}/join", response_model=JoinOut, status_code=status.HTTP_201_CREATED,
             dependencies=[JoinAllowed],
             responses={200: {"model": JoinOut, "description": "this external id joined before: the same participant"},
                        **error_responses(404, 429)})
async def join(study_id: str, ctx: ContextDep, request: Request, response: Response,
               body: JoinIn | None = None) -> dict:
    """Join an open study. A prolific_pid seen before returns the same participant (200) only with the same
    session_id or from the same browser (its cookie); otherwise 409, as when the study is full (its places are
    taken). Too many joins from one address answer 429 with Retry-After."""
    body = body or JoinIn()
    secret = browser_secret(request)
    state, created = await run_in_threadpool(
        services.join_study, ctx, study_id, prolific_pid=body.prolific_pid, external_study_id=body.study_id,
        external_session_id=body.session_id, browser_secret=secret)
    remember_browser(request, response, secret)
    if not created:
        response.status_code = status.HTTP_200_OK
    return {"participant_id": state["participant_id"], "token": state["token"], "created": created, "state": state}


@router.get("/me", response_model=ParticipantState, responses=NOT_MODIFIED)
async def get_state(request: Request, response: Response, ctx: ContextDep, token: TokenDep) -> Any:
    """The participant's current state, with an ETag: a poll that sends it back (If-None-Match) while nothing
    changed is answered 304 from one small query."""
    if request.headers.get("if-none-match"):
        current = await run_in_threadpool(services.current_state_tag, ctx, token)
        if current is not None and client_has(request, current):
            return not_modified(current)
    state, tag = await run_in_threadpool(services.tagged_state, ctx, token)
    tag_answer(response, tag)
    return state


@router.post("/me/consent", response_model=ParticipantState)
async def consent(body: ConsentIn, ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None) -> dict:
    """Agree to (or decline) the consent text of the given version."""
    return await run_in_threadpool(services.give_consent, ctx, token, agree=body.agree,
                                   consent_version=body.consent_version, key=key)


@router.post("/me/instructions", response_model=ParticipantState)
async def instructions(ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None) -> dict:
    """The instructions have been read; the first task starts."""
    return await run_in_threadpool(services.finish_instructions, ctx, token, key=key)


@router.post("/me/placements", response_model=ParticipantState)
async def place(body: PlacementIn, ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None) -> dict:
    """Place one object on the table during a practice trial or demonstration."""
    return await run_in_threadpool(services.place_object, ctx, token, obj=body.object, expect=_expect(body), key=key)


@router.post("/me/demonstration/finish", response_model=ParticipantState)
async def finish(ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None,
                 body: Annotated[StepGuard | None, Body()] = None) -> dict:
    """End the current practice trial or demonstration (stopping before all objects are placed is allowed)."""
    return await run_in_threadpool(services.finish_demonstration, ctx, token, expect=_expect(body), key=key)


@router.post("/me/execution", response_model=ParticipantState)
async def execute(ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None,
                  body: Annotated[StepGuard | None, Body()] = None) -> dict:
    """The robot carries out the current query or test; poll GET /me until execution.status is finished."""
    return await run_in_threadpool(services.start_execution, ctx, token, expect=_expect(body), key=key)


@router.post("/me/assessment", response_model=ParticipantState)
async def assess(body: AssessmentIn, ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None) -> dict:
    """Judge the robot's finished execution acceptable or not."""
    return await run_in_threadpool(services.assess_execution, ctx, token, acceptable=body.acceptable,
                                   expect=_expect(body), key=key, shown_fraction=body.shown_fraction)


@router.post("/me/questionnaire", response_model=ParticipantState)
async def questionnaire(body: QuestionnaireIn, ctx: ContextDep, token: TokenDep,
                        key: IdempotencyKey = None) -> dict:
    """Answer the questionnaire; the answer's state carries the completion code and redirect URL."""
    return await run_in_threadpool(services.answer_questionnaire, ctx, token, answers=body.answers, key=key)


@router.post("/me/quiz", response_model=ParticipantState)
async def quiz(body: QuizIn, ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None) -> dict:
    """Answer the comprehension quiz: all correct starts the first task; too many failed attempts screen out."""
    return await run_in_threadpool(services.answer_quiz, ctx, token, answers=body.answers, key=key)


@router.post("/me/withdraw", response_model=ParticipantState)
async def withdraw(ctx: ContextDep, token: TokenDep, key: IdempotencyKey = None) -> dict:
    """Withdraw from the study (after consent): the participant's recorded data are deleted."""
    return await run_in_threadpool(services.withdraw, ctx, token, key=key)


@router.post("/me/signals", status_code=status.HTTP_204_NO_CONTENT)
async def signal(body: SignalIn, ctx: ContextDep, token: TokenDep) -> Response:
    """Attention telemetry (the tab hidden, the window left, text pasted into an answer: counted per participant)
    or "still_here" (presence: postpones an idle time-out). Nothing the participant sees changes."""
    await run_in_threadpool(attention.record_signal, ctx, token, kind=body.kind, field=body.field)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
