"""Dependencies: the services context, the participant's token and the experimenter check."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Header, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.concurrency import run_in_threadpool

from ..errors import Forbidden, NotAuthenticated, TryLater
from ..services import Context, accounts
from .auth import FailureLimiter, SecretChecker

_participant_bearer = HTTPBearer(auto_error=False, scheme_name="ParticipantToken",
                                 description="the participant's token from their link (/p/{token})")
_experimenter_bearer = HTTPBearer(auto_error=False, scheme_name="ExperimenterToken",
                                  description="the experimenter token or password from the server settings")


# Dependencies that only read the request are async: a sync one costs a trip through the thread pool.
async def get_context(request: Request) -> Context:
    """The services context the app was built with."""
    return request.app.state.context


async def participant_token(
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_participant_bearer)],
) -> str:
    """The bearer token of the participant making the request."""
    if credentials is None or not credentials.credentials:
        raise NotAuthenticated("missing participant token: send Authorization: Bearer <token>")
    return credentials.credentials


async def require_experimenter(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_experimenter_bearer)],
) -> None:
    """Refuse the request unless it carries the server's experimenter key (the bootstrap owner) or a person's valid
    API token whose role allows it (403 otherwise); too many wrong keys from one address get 429."""
    checker: SecretChecker = request.app.state.experimenter
    limiter: FailureLimiter = request.app.state.key_failures
    if credentials is None or not credentials.credentials:
        raise NotAuthenticated("experimenter endpoint: send Authorization: Bearer <experimenter token>")
    client = request.client.host if request.client else "unknown"
    wait = limiter.retry_after(client)
    if wait:
        raise TryLater(f"too many wrong experimenter tokens from this address; try again in {wait} s",
                       retry_after=wait, status=429)
    ok = (await run_in_threadpool(checker.check, credentials.credentials) if checker.slow
          else checker.check(credentials.credentials))
    if ok:
        actor = accounts.BOOTSTRAP
    else:
        found = await run_in_threadpool(accounts.actor_of_token, request.app.state.context, credentials.credentials)
        if found is None:
            limiter.failed(client)
            raise NotAuthenticated("wrong, expired or revoked experimenter token")
        actor = found
    request.state.experimenter = actor  # read by the audit log (web/audit.py), which records refused writes too
    if not accounts.allowed(actor.role, request.method, request.url.path):
        raise Forbidden(f"{actor.name} has the role {actor.role}, which may not {request.method} {request.url.path} "
                        "(analyst: read and export only; experimenter: studies and participants; owner: everything)")


ContextDep = Annotated[Context, Depends(get_context)]
TokenDep = Annotated[str, Depends(participant_token)]
IdempotencyKey = Annotated[
    str | None,
    Header(alias="Idempotency-Key", min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$",
           description="a fresh id per action (e.g. a UUID); repeating it repeats nothing"),
]
Experimenter = Depends(require_experimenter)
# Ids and indices in paths are bounded to what the database stores (a 32-bit integer column): a larger number
# is a 422 naming the parameter, never an OverflowError deep in the database driver.
MAX_ID = 2**31 - 1
ParticipantId = Annotated[int, Path(ge=1, le=MAX_ID, description="the participant's number in the study")]
StepIndex = Annotated[int, Path(ge=0, le=10_000, description="counts from 0")]
