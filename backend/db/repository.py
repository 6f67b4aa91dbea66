"""Repository functions: keyword-only, they flush but never commit (services commit once per action)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import Row, and_, bindparam, delete, func, insert, select
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session
from sqlalchemy.orm.exc import StaleDataError

from .engine import busy, is_busy
from .recording_rows import delete_participant_files
from .tables import ErasureRow, EventRow, ParticipantRow, StudyRow, TaskSessionRow, utcnow

# Participants who left or were erased: they no longer count for balancing and an erased one is shown nowhere.
ENDED_STAGES = ("withdrawn", "screened_out", "erased")


class WriteConflict(Exception):
    """A concurrent writer changed the same rows first, or a unique value already exists."""


_LOST_RACE = (IntegrityError, StaleDataError, OperationalError)


def _lost_race(session: Session, exc: Exception) -> Exception:
    """Roll back (forgetting cached rows) and name the race that was lost (or the busy database: TryLater)."""
    session.rollback()
    session.info.pop("task_sessions", None)
    if is_busy(exc):
        return busy(exc)
    return WriteConflict(str(exc).splitlines()[0])


def commit(session: Session) -> None:
    """Commit; a lost race (stale version, unique clash) becomes WriteConflict, a busy database TryLater."""
    try:
        session.commit()
    except _LOST_RACE as exc:
        raise _lost_race(session, exc) from exc


def flush(session: Session) -> None:
    """Flush pending changes, translating lost races like commit()."""
    try:
        session.flush()
    except _LOST_RACE as exc:
        raise _lost_race(session, exc) from exc


# ------------------------------------------------------------------ studies


_STUDY = select(StudyRow).where(StudyRow.id == bindparam("study_id"))
_STUDY_FOR_UPDATE = _STUDY.with_for_update()


def get_study(session: Session, *, study_id: str, for_update: bool = False) -> StudyRow | None:
    """A study by id (locked for update where the database supports it)."""
    return session.scalars(_STUDY_FOR_UPDATE if for_update else _STUDY, {"study_id": study_id}).one_or_none()


def study_objects_of_participant(session: Session, *, participant_id: int) -> list[dict[str, Any]] | None:
    """The own objects of a participant's study (None: the dinner table, or no such participant)."""
    stmt = select(StudyRow.objects).join(ParticipantRow, ParticipantRow.study_id == StudyRow.id).where(
        ParticipantRow.id == participant_id)
    return session.scalars(stmt).one_or_none()


def list_studies(session: Session) -> list[StudyRow]:
    """Every study, newest first."""
    return list(session.scalars(select(StudyRow).order_by(StudyRow.created_at.desc(), StudyRow.id)))


def delete_study(session: Session, *, study: StudyRow) -> None:
    """Delete a study with its (erased) participant rows and its erasure log."""
    session.execute(delete(ErasureRow).where(ErasureRow.study_id == study.id))
    session.execute(delete(ParticipantRow).where(ParticipantRow.study_id == study.id))
    session.delete(study)
    flush(session)


def add_study(session: Session, *, values: dict[str, Any]) -> StudyRow:
    """Insert a study."""
    row = StudyRow(**values)
    session.add(row)
    flush(session)
    return row


# ------------------------------------------------------------------ participants


# The statements of every participant request are built once: building one costs more than running it.
_REQUEST_BY_TOKEN = (
    select(ParticipantRow, StudyRow, EventRow.kind, EventRow.request_digest)
    .join(StudyRow, StudyRow.id == ParticipantRow.study_id)
    .outerjoin(EventRow, and_(EventRow.participant_id == ParticipantRow.id,
                              EventRow.client_event_id == bindparam("client_event_id")))
    .where(ParticipantRow.token == bindparam("token"))
)
_TASK_SESSION = select(TaskSessionRow).where(
    TaskSessionRow.participant_id == bindparam("participant_id"), TaskSessionRow.task_index == bindparam("task_index")
)
_INSERT_EVENT = insert(EventRow.__table__)


@dataclass(frozen=True)
class EarlierRequest:
    """The event a client stored before under the same idempotency key: its kind and request digest."""

    kind: str
    request_digest: str | None


_LOCK_PARTICIPANT = select(ParticipantRow.id).where(ParticipantRow.token == bindparam("token")).with_for_update()


def lock_participant(session: Session, *, token: str) -> None:
    """Lock the participant's row until the transaction ends, where the database has row locks (PostgreSQL).

    Requests of one participant then run one after another, so a retry with the same idempotency key
    finds the first one's event (a fresh statement sees it under READ COMMITTED) and replays it. SQLite needs
    no lock: its writes are serialised by BEGIN IMMEDIATE."""
    if session.get_bind().dialect.name != "sqlite":
        session.execute(_LOCK_PARTICIPANT, {"token": token})


_LOCK_PARTICIPANT_ID = (select(ParticipantRow.id).where(ParticipantRow.id == bindparam("participant_id"))
                        .with_for_update())


def lock_participant_id(session: Session, *, participant_id: int) -> None:
    """lock_participant by the participant's number (background work knows the number, not the token)."""
    if session.get_bind().dialect.name != "sqlite":
        session.execute(_LOCK_PARTICIPANT_ID, {"participant_id": participant_id})


def get_participant_with_study(session: Session, *, participant_id: int) -> tuple[ParticipantRow, StudyRow] | None:
    """A participant by number with their study (None if there is no such participant)."""
    participant = session.get(ParticipantRow, participant_id, populate_existing=True)
    if participant is None:
        return None
    study = session.get(StudyRow, participant.study_id)
    return None if study is None else (participant, study)


@dataclass(frozen=True)
class PollRow:
    """What a participant's poll needs to tell whether anything changed: one row, no ORM objects."""

    participant_id: int
    participant_version: int
    stage: str
    task_index: int
    study_updated_at: datetime | None
    task_version: int | None  # the current task's session (None outside a task or before it exists)
    execution: dict[str, Any] | None


_POLL_BY_TOKEN = (
    select(ParticipantRow.id, ParticipantRow.version, ParticipantRow.stage, ParticipantRow.task_index,
           StudyRow.updated_at, TaskSessionRow.version, TaskSessionRow.execution)
    .join(StudyRow, StudyRow.id == ParticipantRow.study_id)
    .outerjoin(TaskSessionRow, and_(TaskSessionRow.participant_id == ParticipantRow.id,
                                    TaskSessionRow.task_index == ParticipantRow.task_index))
    .where(ParticipantRow.token == bindparam("token"))
)


def poll_row(session: Session, *, token: str) -> PollRow | None:
    """The versions of a participant's rows (participant, study, current task session), by token; one query."""
    row = session.execute(_POLL_BY_TOKEN, {"token": token}).one_or_none()
    if row is None:
        return None
    pid, version, stage, task_index, study_updated_at, task_version, execution = row
    in_task = stage == "task"
    return PollRow(pid, version, stage, task_index, study_updated_at, task_version if in_task else None,
                   execution if in_task else None)


def get_participant_and_study(session: Session, *, token: str) -> tuple[ParticipantRow, StudyRow] | None:
    """The participant whose secret token this is, with their study (one query)."""
    found = get_participant_for_request(session, token=token, client_event_id=None)
    return None if found is None else found[:2]


def get_participant_for_request(
    session: Session, *, token: str, client_event_id: str | None
) -> tuple[ParticipantRow, StudyRow, EarlierRequest | None] | None:
    """The participant of a token, their study and the earlier request under this idempotency key (one query)."""
    row = session.execute(_REQUEST_BY_TOKEN, {"token": token, "client_event_id": client_event_id}).one_or_none()
    if row is None:
        return None
    participant, study, kind, digest = row
    return participant, study, None if kind is None else EarlierRequest(kind, digest)


def get_participant(session: Session, *, study_id: str, participant_id: int,
                    include_erased: bool = False) -> ParticipantRow | None:
    """A participant of a study by numeric id (an erased one only if include_erased)."""
    stmt = select(ParticipantRow).where(ParticipantRow.study_id == study_id, ParticipantRow.id == participant_id)
    if not include_erased:
        stmt = stmt.where(ParticipantRow.stage != "erased")
    return session.scalars(stmt).one_or_none()


def find_participant_by_external_id(session: Session, *, study_id: str, prolific_pid: str) -> ParticipantRow | None:
    """The participant who joined a study with this external (e.g. Prolific) id."""
    stmt = select(ParticipantRow).where(ParticipantRow.study_id == study_id,
                                        ParticipantRow.prolific_pid == prolific_pid)
    return session.scalars(stmt).one_or_none()


def add_participant(session: Session, *, values: dict[str, Any]) -> ParticipantRow:
    """Insert a participant."""
    row = ParticipantRow(**values)
    session.add(row)
    flush(session)
    return row


def list_participants(session: Session, *, study_id: str, include_pilot: bool = True) -> list[ParticipantRow]:
    """A study's participants in joining order (never the erased ones; pilots unless include_pilot is False)."""
    stmt = (select(ParticipantRow).where(ParticipantRow.study_id == study_id, ParticipantRow.stage != "erased")
            .order_by(ParticipantRow.id))
    if not include_pilot:
        stmt = stmt.where(ParticipantRow.pilot.is_(False))
    return list(session.scalars(stmt))


def _taking_part(study_id: str, active_since: datetime, pilot: bool) -> Any:
    """Participants who hold a place: finished, or under way and active since active_since (pilots with pilots)."""
    return ((ParticipantRow.study_id == study_id) & ParticipantRow.pilot.is_(pilot) & (
        (ParticipantRow.stage == "done") | (
            ParticipantRow.stage.not_in(ENDED_STAGES) & (ParticipantRow.last_activity_at >= active_since))))


def live_assignments(session: Session, *, study_id: str, active_since: datetime,
                     pilot: bool) -> list[tuple[str, list[int] | None, bool]]:
    """Condition, task order and whether they consented, of the participants who count for balancing: finished,
    or under way and active since active_since (pilots only with pilots)."""
    stmt = select(ParticipantRow.condition, ParticipantRow.task_order, ParticipantRow.stage).where(
        _taking_part(study_id, active_since, pilot))
    return [(condition, order, stage != "consent") for condition, order, stage in session.execute(stmt)]


def places_taken(session: Session, *, study_id: str, active_since: datetime, pilot: bool) -> int:
    """How many places of a study are taken, as Prolific counts them: finished plus under way (active since
    active_since; pilots only with pilots)."""
    stmt = select(func.count()).select_from(ParticipantRow).where(_taking_part(study_id, active_since, pilot))
    return int(session.execute(stmt).scalar_one())


def stale_participants(session: Session, *, study_id: str, idle_since: datetime) -> list[ParticipantRow]:
    """Participants of a study still under way whose last request came before idle_since."""
    stmt = select(ParticipantRow).where(
        ParticipantRow.study_id == study_id, ParticipantRow.stage.not_in(("done", *ENDED_STAGES)),
        ParticipantRow.last_activity_at < idle_since)
    return list(session.scalars(stmt))


def delete_participant_data(session: Session, *, participant_id: int) -> None:
    """Delete a participant's events, teaching sessions (their answers and beliefs live there) and the rows of their
    recordings kept in the database."""
    session.info.pop("task_sessions", None)
    session.execute(delete(EventRow).where(EventRow.participant_id == participant_id))
    session.execute(delete(TaskSessionRow).where(TaskSessionRow.participant_id == participant_id))
    uid = session.scalar(select(ParticipantRow.uid).where(ParticipantRow.id == participant_id))
    if uid is not None:  # recordings kept in the database (their bytes are swept after the commit)
        delete_participant_files(session, uid)


def uids_without_data(session: Session, *, uids: list[str]) -> list[str]:
    """Which of these participant uids belong to participants whose data are deleted (withdrawn or erased)."""
    stmt = select(ParticipantRow.uid).where(ParticipantRow.uid.in_(uids),
                                            ParticipantRow.stage.in_(("withdrawn", "erased")))
    return sorted(session.scalars(stmt))


def add_erasure(session: Session, *, values: dict[str, Any]) -> ErasureRow:
    """Record an erasure in the audit log."""
    row = ErasureRow(**values)
    session.add(row)
    flush(session)
    return row


def list_erasures(session: Session, *, study_id: str) -> list[ErasureRow]:
    """A study's erasure audit entries, oldest first."""
    stmt = select(ErasureRow).where(ErasureRow.study_id == study_id).order_by(ErasureRow.id)
    return list(session.scalars(stmt))


_COUNT_BY_CONDITION = (
    select(ParticipantRow.condition, func.count())
    .where(
        ParticipantRow.study_id == bindparam("study_id"),
        (ParticipantRow.stage == "done") | (
            ParticipantRow.stage.not_in(ENDED_STAGES) & (ParticipantRow.last_activity_at >= bindparam("active_since"))
        ),
    )
    .group_by(ParticipantRow.condition)
)


def count_by_condition(session: Session, *, study_id: str, active_since: datetime) -> dict[str, int]:
    """Participants per condition who finished or whose last request came after active_since."""
    params = {"study_id": study_id, "active_since": active_since}
    return {condition: int(n) for condition, n in session.execute(_COUNT_BY_CONDITION, params)}


def touch(participant: ParticipantRow) -> None:
    """Record activity now."""
    participant.last_activity_at = utcnow()


# ------------------------------------------------------------------ task sessions


def get_task_session(session: Session, *, participant_id: int, task_index: int) -> TaskSessionRow | None:
    """A participant's teaching session for one task (remembered for the rest of the transaction)."""
    cache = session.info.setdefault("task_sessions", {})
    row = cache.get((participant_id, task_index))
    if row is not None:
        return row
    row = session.scalars(_TASK_SESSION, {"participant_id": participant_id, "task_index": task_index}).one_or_none()
    if row is not None:
        cache[(participant_id, task_index)] = row
    return row


def add_task_session(session: Session, *, participant_id: int, task_index: int, state_json: str) -> TaskSessionRow:
    """Insert a participant's teaching session for one task."""
    row = TaskSessionRow(
        participant_id=participant_id, task_index=task_index, state_json=state_json, demo_placed=[], demo_trace=[]
    )
    session.add(row)
    flush(session)
    session.info.setdefault("task_sessions", {})[(participant_id, task_index)] = row
    return row


def current_task_sessions(session: Session, *, study_id: str) -> dict[int, TaskSessionRow]:
    """The teaching session each participant of a study is in now (those at the task stage), by participant id."""
    stmt = (
        select(TaskSessionRow)
        .join(ParticipantRow, and_(TaskSessionRow.participant_id == ParticipantRow.id,
                                   TaskSessionRow.task_index == ParticipantRow.task_index))
        .where(ParticipantRow.study_id == study_id, ParticipantRow.stage == "task")
    )
    return {ts.participant_id: ts for ts in session.scalars(stmt)}


def task_sessions_of(session: Session, *, participant_id: int) -> list[TaskSessionRow]:
    """A participant's teaching sessions in task order."""
    stmt = (select(TaskSessionRow).where(TaskSessionRow.participant_id == participant_id)
            .order_by(TaskSessionRow.task_index))
    return list(session.scalars(stmt))


# ------------------------------------------------------------------ events


def append_event(
    session: Session,
    *,
    participant: ParticipantRow,
    kind: str,
    payload: dict[str, Any],
    app_version: str,
    task_index: int | None = None,
    step_kind: str | None = None,
    step_index: int | None = None,
    client_event_id: str | None = None,
    request_digest: str | None = None,
) -> None:
    """Append one event to a participant's log (sequence numbers are dense per participant).

    The row is inserted at once, without the ORM's unit of work (the hot path of every request); a clash
    with a stored sequence number or idempotency key raises WriteConflict here rather than at commit."""
    participant.n_events = (participant.n_events or 0) + 1
    participant.last_activity_at = utcnow()
    values = {
        "participant_id": participant.id, "seq": participant.n_events, "client_event_id": client_event_id,
        "request_digest": request_digest, "kind": kind, "task_index": task_index, "step_kind": step_kind,
        "step_index": step_index, "payload": payload, "app_version": app_version,
        "created_at": participant.last_activity_at,
    }
    try:
        with session.no_autoflush:  # the participant's row exists; its changes are flushed at commit
            session.execute(_INSERT_EVENT, values)
    except _LOST_RACE as exc:
        raise _lost_race(session, exc) from exc


# ------------------------------------------------------------------ exports


def count_study_events(session: Session, *, study_id: str) -> dict[int, int]:
    """Stored events per participant of a study (what events.csv holds for each)."""
    stmt = (select(EventRow.participant_id, func.count())
            .join(ParticipantRow, EventRow.participant_id == ParticipantRow.id)
            .where(ParticipantRow.study_id == study_id).group_by(EventRow.participant_id))
    return {pid: n for pid, n in session.execute(stmt)}


def iter_study_events(session: Session, *, study_id: str, kind: str | None = None,
                      include_pilot: bool = True) -> Iterator[EventRow]:
    """A study's events (optionally of one kind; pilots' unless include_pilot is False) by participant then
    sequence, fetched in batches."""
    stmt = (
        select(EventRow)
        .join(ParticipantRow, EventRow.participant_id == ParticipantRow.id)
        .where(ParticipantRow.study_id == study_id)
        .order_by(EventRow.participant_id, EventRow.seq)
        .execution_options(yield_per=500)
    )
    if kind is not None:
        stmt = stmt.where(EventRow.kind == kind)
    if not include_pilot:
        stmt = stmt.where(ParticipantRow.pilot.is_(False))
    yield from session.scalars(stmt)


def iter_study_task_sessions(session: Session, *, study_id: str,
                             include_pilot: bool = True) -> Iterator[TaskSessionRow]:
    """A study's teaching sessions (pilots' unless include_pilot is False) by participant then task."""
    stmt = (
        select(TaskSessionRow)
        .join(ParticipantRow, TaskSessionRow.participant_id == ParticipantRow.id)
        .where(ParticipantRow.study_id == study_id)
        .order_by(TaskSessionRow.participant_id, TaskSessionRow.task_index)
        .execution_options(yield_per=200)
    )
    if not include_pilot:
        stmt = stmt.where(ParticipantRow.pilot.is_(False))
    yield from session.scalars(stmt)


def event_times(session: Session, *, participant_id: int, kinds: tuple[str, ...]) -> list[Row[Any]]:
    """One participant's events of the given kinds, in order, as plain rows of what a timeline needs (kind, step,
    payload, created_at): read on every state view, so without the ORM's per-object bookkeeping."""
    stmt = (select(EventRow.kind, EventRow.task_index, EventRow.step_kind, EventRow.step_index, EventRow.payload,
                   EventRow.created_at)
            .where(EventRow.participant_id == participant_id, EventRow.kind.in_(kinds)).order_by(EventRow.seq))
    return list(session.execute(stmt))


def participant_events(session: Session, *, participant_id: int, kinds: tuple[str, ...]) -> list[EventRow]:
    """One participant's events of the given kinds, in order."""
    stmt = (select(EventRow).where(EventRow.participant_id == participant_id, EventRow.kind.in_(kinds))
            .order_by(EventRow.seq))
    return list(session.scalars(stmt))
