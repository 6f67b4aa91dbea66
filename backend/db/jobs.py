"""The jobs table's queries (services.runtime): add in an action's transaction, claim with a lease, finish, retry.

A claim is a lease: the job is taken by one process until `claimed_until`; if that process dies, any live
process claims it again once the lease has run out. On PostgreSQL the claim skips rows another process is
claiming at the same moment (FOR UPDATE SKIP LOCKED); SQLite serialises writers, so one claim runs at a time.
Like the other repository functions these flush but never commit.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import and_, case, delete, func, not_, or_, select, update
from sqlalchemy.orm import Session

from .tables import JobRow, utcnow


@dataclass(frozen=True)
class ClaimedJob:
    """A job this process holds until its lease ends: what to do, for whom, and how often it was tried."""

    id: int
    kind: str
    participant_id: int
    task_index: int | None
    payload: dict[str, Any]
    attempts: int


def add_job(session: Session, *, kind: str, participant_id: int, task_index: int | None,
            payload: dict[str, Any], due_at: datetime | None = None, held_for: str | None = None,
            held_seconds: float = 0.0) -> None:
    """Record work to do once this transaction commits (at due_at, default now). A job `held_for` a process is its
    to claim for `held_seconds` past due (a lease it has not taken up yet: attempts stay 0); after that, any
    process's."""
    due = due_at or utcnow()
    held_until = due + timedelta(seconds=held_seconds) if held_for is not None else None
    session.add(JobRow(kind=kind, participant_id=participant_id, task_index=task_index, payload=payload,
                       due_at=due, attempts=0, claimed_by=held_for, claimed_until=held_until))


def _held_for(owner: str) -> Any:
    """A job held for `owner` that it has not taken up yet (a claim sets attempts to 1 or more, so a job under way is
    never claimed twice); never NULL."""
    return and_(func.coalesce(JobRow.claimed_by, "") == owner, JobRow.attempts == 0)


def _of_kinds(query: Any, kinds: Collection[str] | None) -> Any:
    """The query restricted to jobs of these kinds (None: any)."""
    return query if kinds is None else query.where(JobRow.kind.in_(sorted(kinds)))


def claim_jobs(session: Session, *, owner: str, lease_seconds: float, limit: int, now: datetime | None = None,
               kinds: Collection[str] | None = None, first: Collection[str] = ()) -> list[ClaimedJob]:
    """Take up to `limit` due jobs that nobody holds (or whose holder's lease ran out, or held for `owner`): of these
    kinds (None: any), the kinds in `first` before the others, then oldest due first."""
    now = now or utcnow()
    free = or_(JobRow.claimed_until.is_(None), JobRow.claimed_until < now, _held_for(owner))
    query = _of_kinds(select(JobRow).where(JobRow.due_at <= now, free), kinds)
    if first:
        query = query.order_by(case((JobRow.kind.in_(sorted(first)), 0), else_=1))
    query = query.order_by(JobRow.due_at, JobRow.id).limit(limit)
    if session.get_bind().dialect.name != "sqlite":
        query = query.with_for_update(skip_locked=True)
    rows = list(session.execute(query).scalars())
    until = now + timedelta(seconds=lease_seconds)
    for row in rows:
        row.claimed_by, row.claimed_until, row.attempts = owner, until, row.attempts + 1
    session.flush()
    return [ClaimedJob(r.id, r.kind, r.participant_id, r.task_index, dict(r.payload), r.attempts) for r in rows]


def finish_job(session: Session, *, job_id: int) -> None:
    """The job is done: remove it."""
    session.execute(delete(JobRow).where(JobRow.id == job_id))


def retry_job(session: Session, *, job_id: int, due_at: datetime, error: str) -> None:
    """The job failed: release it to run again at due_at, keeping the error."""
    session.execute(update(JobRow).where(JobRow.id == job_id)
                    .values(due_at=due_at, claimed_by=None, claimed_until=None, last_error=error[:2000]))


def release_claims(session: Session) -> int:
    """Free every claim (a process starting on SQLite, the only process there: its predecessor's claims are void)."""
    result = session.execute(update(JobRow).where(JobRow.claimed_by.is_not(None))
                             .values(claimed_by=None, claimed_until=None))
    return int(result.rowcount or 0)  # type: ignore[attr-defined]


def next_claimable(session: Session, *, owner: str, kinds: Collection[str] | None = None) -> datetime | None:
    """When the earliest job (of these kinds; None: any) can next be claimed by `owner`: when due, or once its
    holder's lease runs out unless it is held for `owner`; None without such jobs. A read: a runner asks this
    before it takes the write lock to claim."""
    leased = and_(JobRow.claimed_until.is_not(None), JobRow.claimed_until > JobRow.due_at, not_(_held_for(owner)))
    claimable_at = case((leased, JobRow.claimed_until), else_=JobRow.due_at)
    return session.execute(_of_kinds(select(func.min(claimable_at)), kinds)).scalar_one_or_none()


def pending_jobs(session: Session, *, participant_id: int | None = None) -> list[JobRow]:
    """Jobs not yet done (all, or one participant's), oldest first; for tests, tools and the dashboard."""
    query = select(JobRow).order_by(JobRow.due_at, JobRow.id)
    if participant_id is not None:
        query = query.where(JobRow.participant_id == participant_id)
    return list(session.execute(query).scalars())
