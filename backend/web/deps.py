"""Dependencies: the services context, the participant's token and the experimenter check."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Header, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.concurrency import run_in_threadpool

from ..errors import Forbidden, NotAuthenticated, TryLater
from ..services import Context, accounts
from .auth import SecretChecker
from .limits import AddressLimiter

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
    limiter: AddressLimiter = request.app.state.key_failures
    if credentials is None or not credentials.credentials:
        raise NotAuthenticated("experimenter endpoint: send Authorization: Bearer <experimenter token>")
    secret = credentials.credentials
    # The right key always works: a limit on it would let anyone behind the same address (a campus NAT) keep
    # the experimenter out with one wrong key now and then. Only wrong keys are counted and limited.
    known = checker.quick_check(secret)
    if known:
        _authorize(request, accounts.BOOTSTRAP)
        return
    person = await run_in_threadpool(accounts.actor_of_token, request.app.state.context, secret)
    if person is not None:
        _authorize(request, person)
        return
    client = request.client.host if request.client else "unknown"
    wait = limiter.retry_after(client)
    if wait:
        raise TryLater(f"too many wrong experimenter tokens from this address; try again in {wait} s",
                       retry_after=wait, status=429)
    ok = known if known is not None else await run_in_threadpool(checker.check, secret)  # legacy PBKDF2: slow
    if not ok:
        limiter.record(client)
        raise NotAuthenticated("wrong, expired or revoked experimenter token")
    _authorize(request, accounts.BOOTSTRAP)


def _authorize(request: Request, actor: accounts.Actor) -> None:
    """Note who acts (the audit log reads it, refused writes included) and refuse what their role may not do."""
    request.state.experimenter = actor
    if not accounts.allowed(actor.role, request.method, request.url.path):
        raise Forbidden(f"{actor.name} has the role {actor.role}, which may not {request.method} {request.url.path} "
                        "(analyst: read and export only; experimenter: studies and participants; owner: everything)")


async def acting_person(request: Request, _: Annotated[None, Depends(require_experimenter)]) -> accounts.Actor:
    """Who makes this experimenter request (the check runs once per request: FastAPI caches it)."""
    return request.state.experimenter


async def join_allowed(request: Request) -> None:
    """Refuse a join with 429 once this client address has made joins_per_address of them in the window."""
    limiter: AddressLimiter = request.app.state.joins
    client = request.client.host if request.client else "unknown"
    wait = limiter.retry_after(client)
    if wait:
        raise TryLater(f"too many joins from this address ({limiter.limit} in {limiter.window:g} s); try again in "
                       f"{wait} s", retry_after=wait, status=429)
    limiter.record(client)


ContextDep = Annotated[Context, Depends(get_context)]
TokenDep = Annotated[str, Depends(participant_token)]
IdempotencyKey = Annotated[
    str | None,
    Header(alias="Idempotency-Key", min_length=1, max_length=128, pattern=r"^[A-Za-z0-9_.:\-]+$",
           description="a fresh id per action (e.g. a UUID); repeating it repeats nothing"),
]
Experimenter = Depends(require_experimenter)
ActorDep = Annotated[accounts.Actor, Depends(acting_person)]
JoinAllowed = Depends(join_allowed)
# Ids and indices in paths are bounded to what the database stores (a 32-bit integer column): a larger number
# is a 422 naming the parameter, never an OverflowError deep in the database driver.
MAX_ID = 2**31 - 1
ParticipantId = Annotated[int, Path(ge=1, le=MAX_ID, description="the participant's number in the study")]
StepIndex = Annotated[int, Path(ge=0, le=10_000, description="counts from 0")]
