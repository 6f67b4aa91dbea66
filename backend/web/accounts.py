"""Experimenter accounts over HTTP: people and their API tokens (owner only), the dashboard's password login, who
is logged in, and the audit log (JSON and CSV)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Request
from fastapi.responses import StreamingResponse
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from ..errors import InvalidFields, NotAuthenticated, TryLater
from ..services import accounts
from .limits import AddressLimiter
from .deps import MAX_ID, ContextDep, Experimenter
from .exports import csv_lines
from .schemas import error_responses

router = APIRouter(prefix="/api/v1", tags=["accounts"], dependencies=[Experimenter],
                   responses=error_responses(400, 401, 404, 409, 422))
public = APIRouter(prefix="/api/v1", tags=["accounts"], responses=error_responses(400, 401, 422, 429))
TokenId = Annotated[int, Path(ge=1, le=MAX_ID, description="the API token's number")]


class NewPerson(BaseModel):
    """An account to create."""

    name: str = Field(min_length=1, max_length=64)
    role: str = Field(description="owner, experimenter or analyst")
    password: str | None = Field(None, max_length=1000, description="for the dashboard login (12+ characters)")


class NewToken(BaseModel):
    """An API token to issue."""

    label: str = Field("api", max_length=100)
    days: float = Field(90, gt=0, le=accounts.MAX_TOKEN_DAYS, description="valid for this many days")


class NewPassword(BaseModel):
    """The logged-in person's password change."""

    current_password: str = Field(min_length=1, max_length=1000)
    new_password: str = Field(min_length=accounts.MIN_PASSWORD_LENGTH, max_length=1000)


class PasswordSet(BaseModel):
    """A password an owner sets for a person."""

    password: str = Field(min_length=accounts.MIN_PASSWORD_LENGTH, max_length=1000)


class Login(BaseModel):
    """A dashboard login."""

    name: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1000)


class PersonOut(BaseModel):
    """An account."""

    name: str
    role: str = Field(description="owner, experimenter or analyst")
    has_password: bool = Field(description="whether the person can log in to the dashboard with a password")
    created_at: str | None
    disabled_at: str | None = Field(description="when the account was disabled (empty: it is active)")


class PasswordSetOut(PersonOut):
    """An account after its password was set or changed."""

    ended_logins: int = Field(description="how many of the person's dashboard logins were ended")


class TokenOut(BaseModel):
    """An API token's record (never the token itself)."""

    id: int
    name: str = Field(description="the person it belongs to")
    label: str
    created_at: str | None
    expires_at: str | None
    revoked_at: str | None


class IssuedTokenOut(TokenOut):
    """A new API token: the token is in this answer only."""

    token: str


class AuditEntryOut(BaseModel):
    """One experimenter write: who, what, its answer's status, when and from where."""

    at: str | None
    actor: str
    role: str
    method: str
    path: str
    status: int
    client: str


class LoginOut(BaseModel):
    """A dashboard login's token."""

    token: str
    name: str
    role: str
    expires_at: str | None


class WhoamiOut(BaseModel):
    """Who is behind a token."""

    name: str
    role: str
    server_key: bool = Field(description="the server's experimenter key (the bootstrap owner: no account, no "
                                         "password), not a person's token")


@router.get("/whoami", response_model=WhoamiOut)
async def whoami(request: Request) -> dict[str, Any]:
    """The name and role behind the token of this request."""
    actor: accounts.Actor = request.state.experimenter
    return {"name": actor.name, "role": actor.role, "server_key": actor.token_id is None}


@router.post("/accounts", status_code=201, response_model=PersonOut)
def add_person(body: NewPerson, ctx: ContextDep) -> dict[str, Any]:
    """Create an account (owner only); 409 if the name is taken."""
    return accounts.add_person(ctx, body.name, body.role, body.password)


@router.get("/accounts", response_model=list[PersonOut])
def list_people(ctx: ContextDep) -> list[dict[str, Any]]:
    """Every account (owner only)."""
    return accounts.people(ctx)


@router.post("/accounts/{name}/disable", response_model=PersonOut)
def disable_person(name: str, ctx: ContextDep) -> dict[str, Any]:
    """Disable an account; its tokens stop working at once (owner only)."""
    return accounts.disable_person(ctx, name)


@router.post("/accounts/{name}/password", response_model=PasswordSetOut)
def set_password(name: str, body: PasswordSet, ctx: ContextDep) -> dict[str, Any]:
    """Set a person's password, e.g. a forgotten one (owner only); their dashboard logins end."""
    return accounts.set_password(ctx, name, body.password)


@router.post("/password", response_model=PasswordSetOut, responses=error_responses(429))
async def change_password(body: NewPassword, request: Request, ctx: ContextDep) -> dict[str, Any]:
    """Change your own password (every role; not the server key, which has none); your other dashboard logins
    end, this one and your API tokens stay. A wrong current password counts towards the per-address limit on
    wrong keys."""
    limiter: AddressLimiter = request.app.state.key_failures
    client = request.client.host if request.client else "unknown"
    wait = limiter.retry_after(client)
    if wait:
        raise TryLater(f"too many wrong passwords from this address; try again in {wait} s", retry_after=wait,
                       status=429)
    changed = await run_in_threadpool(accounts.change_password, ctx, request.state.experimenter,
                                      body.current_password, body.new_password)
    if changed is None:
        limiter.record(client)
        raise InvalidFields([{"field": "current_password", "message": "is not your current password"}])
    return changed


@router.post("/accounts/{name}/tokens", status_code=201, response_model=IssuedTokenOut)
def issue_token(name: str, body: NewToken, ctx: ContextDep) -> dict[str, Any]:
    """A new API token for the person (owner only): the token is in this answer only."""
    token, record = accounts.issue_token(ctx, name, body.label, body.days)
    return {"token": token, **record}


@router.get("/accounts/all-tokens", response_model=list[TokenOut])
def list_tokens(ctx: ContextDep) -> list[dict[str, Any]]:
    """Every API token's record, never the token (owner only)."""
    return accounts.tokens(ctx)


@router.delete("/accounts/tokens/{token_id}", response_model=TokenOut)
def revoke_token(token_id: TokenId, ctx: ContextDep) -> dict[str, Any]:
    """Revoke a token; it stops working at once (owner only)."""
    return accounts.revoke_token(ctx, token_id)


@router.get("/audit", response_model=list[AuditEntryOut])
def audit(ctx: ContextDep, limit: int = 1000) -> list[dict[str, Any]]:
    """The audit log, newest first: every experimenter write with who, what, its status, when and from where."""
    return accounts.audit_entries(ctx, max(1, min(limit, 100_000)))


@router.get("/audit.csv", response_class=StreamingResponse,
            responses={200: {"content": {"text/csv": {}}, "description": "the audit log as CSV"}})
def audit_csv(ctx: ContextDep) -> StreamingResponse:
    """The whole audit log as CSV (columns at, actor, role, method, path, status, client), oldest first."""
    entries = list(reversed(accounts.audit_entries(ctx, 10_000_000)))
    rows = [list(accounts.AUDIT_COLUMNS)] + [[e[c] for c in accounts.AUDIT_COLUMNS] for e in entries]
    return StreamingResponse(csv_lines(rows), media_type="text/csv; charset=utf-8",
                             headers={"Content-Disposition": 'attachment; filename="audit.csv"'})


@public.post("/login", response_model=LoginOut)
async def login(body: Login, request: Request, ctx: ContextDep) -> dict[str, Any]:
    """Log in to the dashboard with a name and password: a token for 12 hours. Wrong ones count towards the
    per-address limit on wrong experimenter keys."""
    limiter: AddressLimiter = request.app.state.key_failures
    client = request.client.host if request.client else "unknown"
    wait = limiter.retry_after(client)
    if wait:
        raise TryLater(f"too many wrong logins from this address; try again in {wait} s", retry_after=wait,
                       status=429)
    issued = await run_in_threadpool(accounts.login, ctx, body.name, body.password)
    if issued is None:
        limiter.record(client)
        raise NotAuthenticated("wrong name or password")
    token, record = issued
    people = {p["name"]: p for p in await run_in_threadpool(accounts.people, ctx)}
    actor = accounts.Actor(body.name, people[body.name]["role"])
    request.state.experimenter = actor  # the login itself goes into the audit log
    return {"token": token, "name": actor.name, "role": actor.role, "expires_at": record["expires_at"]}
