"""Experimenter accounts: people with roles, their API tokens (expiring, revocable), password logins, and the audit
log of every experimenter write. The environment's experimenter key stays the bootstrap owner."""

from __future__ import annotations

import hashlib
import re
import secrets
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Any

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError
from sqlalchemy import select

from ..db.tables import ApiTokenRow, AuditRow, ExperimenterRow
from ..errors import Conflict, InvalidFields, NotFound
from .context import Context, aware, iso

ROLES = ("owner", "experimenter", "analyst")
BOOTSTRAP_NAME = "owner (server key)"
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9 ._@-]{0,63}$")
MIN_PASSWORD_LENGTH = 12
LOGIN_HOURS = 12
MAX_TOKEN_DAYS = 366
READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
ACCOUNTS_PATH = "/api/v1/accounts"
PASSWORD_PATH = "/api/v1/password"  # a person changes their own password: every role may
LOGIN_LABEL = "dashboard login"
_hasher = PasswordHasher()  # argon2id with the library's recommended parameters


@dataclass(frozen=True)
class Actor:
    """Who makes an experimenter request: a person's name (or the server key's) and their role."""

    name: str
    role: str
    token_id: int | None = None  # the personal API token the request came with (None: the server key)


BOOTSTRAP = Actor(BOOTSTRAP_NAME, "owner")


def allowed(role: str, method: str, path: str) -> bool:
    """Whether a role may make this request: owner everything; experimenter studies and participants (not the
    accounts); analyst only reads and exports. Every role may change its own password."""
    if role == "owner" or (path == PASSWORD_PATH and role in ROLES):
        return True
    if role == "experimenter":
        return not path.startswith(ACCOUNTS_PATH)
    return role == "analyst" and method in READ_METHODS and not path.startswith(ACCOUNTS_PATH)


def digest(token: str) -> str:
    """How a token is stored: its SHA-256 (tokens are random, so no salt or stretching is needed)."""
    return hashlib.sha256(token.encode()).hexdigest()


def _now() -> datetime:
    return datetime.now(timezone.utc)


def _person_json(row: ExperimenterRow) -> dict[str, Any]:
    return {"name": row.name, "role": row.role, "has_password": row.password_hash is not None,
            "created_at": iso(row.created_at), "disabled_at": iso(row.disabled_at)}


def _check_person(name: str, role: str, password: str | None) -> None:
    problems = []
    if not NAME_PATTERN.match(name):
        problems.append({"field": "name", "message": "expected 1-64 letters, digits, spaces or . _ @ -, "
                                                     "starting with a letter or digit"})
    if role not in ROLES:
        problems.append({"field": "role", "message": f"expected one of {', '.join(ROLES)}, got {role!r}"})
    if password is not None and len(password) < MIN_PASSWORD_LENGTH:
        problems.append({"field": "password", "message": f"expected at least {MIN_PASSWORD_LENGTH} characters"})
    if problems:
        raise InvalidFields(problems)


def add_person(ctx: Context, name: str, role: str, password: str | None = None) -> dict[str, Any]:
    """A new experimenter account (Conflict if the name is taken); the password is stored as its argon2 hash."""
    _check_person(name, role, password)
    hashed = _hasher.hash(password) if password is not None else None
    with ctx.db.write() as s:
        if s.scalar(select(ExperimenterRow).where(ExperimenterRow.name == name)) is not None:
            raise Conflict(f"an account named {name!r} exists already")
        row = ExperimenterRow(name=name, role=role, password_hash=hashed, created_at=_now())
        s.add(row)
        s.commit()
        return _person_json(row)


def people(ctx: Context) -> list[dict[str, Any]]:
    """Every account, by name."""
    with ctx.db.read() as s:
        return [_person_json(r) for r in s.scalars(select(ExperimenterRow).order_by(ExperimenterRow.name))]


def _person(s: Any, name: str) -> ExperimenterRow:
    row = s.scalar(select(ExperimenterRow).where(ExperimenterRow.name == name))
    if row is None:
        raise NotFound(f"no account named {name!r}")
    return row


def disable_person(ctx: Context, name: str) -> dict[str, Any]:
    """Disable an account: its tokens stop working at once (repeating it changes nothing)."""
    with ctx.db.write() as s:
        row = _person(s, name)
        if row.disabled_at is None:
            row.disabled_at = _now()
            s.commit()
        return _person_json(row)


def _token_json(row: ApiTokenRow, name: str) -> dict[str, Any]:
    return {"id": row.id, "name": name, "label": row.label, "created_at": iso(row.created_at),
            "expires_at": iso(row.expires_at), "revoked_at": iso(row.revoked_at)}


def issue_token(ctx: Context, name: str, label: str, days: float) -> tuple[str, dict[str, Any]]:
    """A new API token for a person, valid for `days`; the token (shown once) and its record."""
    if not 0 < days <= MAX_TOKEN_DAYS:
        raise InvalidFields([{"field": "days", "message": f"expected more than 0 and at most {MAX_TOKEN_DAYS}"}])
    token = "tt_" + secrets.token_urlsafe(32)
    with ctx.db.write() as s:
        person = _person(s, name)
        if person.disabled_at is not None:
            raise Conflict(f"the account {name!r} is disabled")
        now = _now()
        row = ApiTokenRow(experimenter_id=person.id, digest=digest(token), label=label[:100], created_at=now,
                          expires_at=now + timedelta(days=days))
        s.add(row)
        s.commit()
        return token, _token_json(row, name)


def tokens(ctx: Context) -> list[dict[str, Any]]:
    """Every token's record (never the token itself), newest first; dashboard logins only while they work (else
    every login would add a line for good; the audit log keeps who logged in)."""
    ended_login = (ApiTokenRow.label == LOGIN_LABEL) & (ApiTokenRow.revoked_at.is_not(None)
                                                        | (ApiTokenRow.expires_at <= _now()))
    with ctx.db.read() as s:
        rows = s.execute(select(ApiTokenRow, ExperimenterRow.name).join(ExperimenterRow).where(~ended_login)
                         .order_by(ApiTokenRow.id.desc())).all()
        return [_token_json(row, name) for row, name in rows]


def revoke_token(ctx: Context, token_id: int) -> dict[str, Any]:
    """Revoke a token: it stops working at once (repeating it changes nothing)."""
    with ctx.db.write() as s:
        row = s.get(ApiTokenRow, token_id)
        if row is None:
            raise NotFound(f"no API token {token_id}")
        if row.revoked_at is None:
            row.revoked_at = _now()
            s.commit()
        person = s.get(ExperimenterRow, row.experimenter_id)
        return _token_json(row, person.name if person else "?")


def actor_of_token(ctx: Context, token: str) -> Actor | None:
    """The person a token belongs to, if it is theirs, not expired, not revoked and their account is enabled."""
    with ctx.db.read() as s:
        found = s.execute(select(ApiTokenRow, ExperimenterRow).join(ExperimenterRow)
                          .where(ApiTokenRow.digest == digest(token))).first()
        if found is None:
            return None
        row, person = found
        expires = aware(row.expires_at)
        if row.revoked_at is not None or person.disabled_at is not None or expires is None or expires <= _now():
            return None
        return Actor(person.name, person.role, row.id)


def login(ctx: Context, name: str, password: str) -> tuple[str, dict[str, Any]] | None:
    """A dashboard login: a token valid for LOGIN_HOURS if the password is right (argon2 check), else None."""
    with ctx.db.read() as s:
        person = s.scalar(select(ExperimenterRow).where(ExperimenterRow.name == name))
        stored = None if person is None or person.disabled_at is not None else person.password_hash
    if stored is None:
        _hasher.hash(password)  # the same work as a check, so a wrong name takes as long as a wrong password
        return None
    try:
        _hasher.verify(stored, password)
    except (VerificationError, InvalidHashError):
        return None
    return issue_token(ctx, name, LOGIN_LABEL, LOGIN_HOURS / 24)


def _check_new_password(password: str, field: str) -> None:
    if len(password) < MIN_PASSWORD_LENGTH:
        raise InvalidFields([{"field": field, "message": f"expected at least {MIN_PASSWORD_LENGTH} characters"}])


def _end_logins(s: Any, person: ExperimenterRow, keep: int | None) -> int:
    """Revoke the person's dashboard logins (not their labelled API tokens), all but `keep`; how many."""
    now = _now()
    rows = s.scalars(select(ApiTokenRow).where(ApiTokenRow.experimenter_id == person.id,
                                               ApiTokenRow.label == LOGIN_LABEL,
                                               ApiTokenRow.revoked_at.is_(None))).all()
    ended = [r for r in rows if r.id != keep and (aware(r.expires_at) or now) > now]
    for r in ended:
        r.revoked_at = now
    return len(ended)


def change_password(ctx: Context, actor: Actor, current: str, new: str) -> dict[str, Any] | None:
    """The logged-in person changes their own password (argon2 check of the current one); their other dashboard
    logins end. None if the current password is wrong; Conflict for the server key, which has no account."""
    if actor.token_id is None:
        raise Conflict("you are logged in with the server's experimenter key, which has no account and no password "
                       "(it is set in the server's environment); log in as a person to change a password")
    _check_new_password(new, "new_password")
    if new == current:
        raise InvalidFields([{"field": "new_password", "message": "is the current password; expected a new one"}])
    with ctx.db.read() as s:
        stored = _person(s, actor.name).password_hash
    if stored is None:
        raise Conflict(f"the account {actor.name!r} has no password yet; an owner sets one on the Accounts page")
    try:
        _hasher.verify(stored, current)
    except (VerificationError, InvalidHashError):
        return None
    hashed = _hasher.hash(new)
    with ctx.db.write() as s:
        person = _person(s, actor.name)
        person.password_hash = hashed
        ended = _end_logins(s, person, keep=actor.token_id)
        s.commit()
        return {**_person_json(person), "ended_logins": ended}


def set_password(ctx: Context, name: str, password: str) -> dict[str, Any]:
    """An owner sets a person's password (a forgotten one, or a first one); the person's dashboard logins end."""
    _check_new_password(password, "password")
    hashed = _hasher.hash(password)
    with ctx.db.write() as s:
        person = _person(s, name)
        if person.disabled_at is not None:
            raise Conflict(f"the account {name!r} is disabled")
        person.password_hash = hashed
        ended = _end_logins(s, person, keep=None)
        s.commit()
        return {**_person_json(person), "ended_logins": ended}


def record_write(ctx: Context, actor: Actor, method: str, path: str, status: int, client: str) -> None:
    """Append one experimenter write to the audit log."""
    with ctx.db.write() as s:
        s.add(AuditRow(at=_now(), actor=actor.name, role=actor.role, method=method, path=path[:500], status=status,
                       client=client[:64]))
        s.commit()


AUDIT_COLUMNS = ("at", "actor", "role", "method", "path", "status", "client")


def audit_entries(ctx: Context, limit: int = 1000) -> list[dict[str, Any]]:
    """The newest audit entries first (who, what, when, from where, and the answer's status)."""
    with ctx.db.read() as s:
        rows = s.scalars(select(AuditRow).order_by(AuditRow.id.desc()).limit(limit)).all()
        return [{"at": iso(r.at), "actor": r.actor, "role": r.role, "method": r.method, "path": r.path,
                 "status": r.status, "client": r.client} for r in rows]
