"""Read-only queries the experimenter's analysis views need beyond repository.py (keyword-only, never write)."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from .tables import EventRow, ParticipantRow, TaskSessionRow


def participant_events(session: Session, *, participant_id: int) -> list[EventRow]:
    """One participant's events in log order."""
    stmt = select(EventRow).where(EventRow.participant_id == participant_id).order_by(EventRow.seq)
    return list(session.scalars(stmt))


def study_task_sessions_with_participants(session: Session, *, study_id: str, include_pilot: bool = True,
                                          ) -> list[tuple[TaskSessionRow, ParticipantRow]]:
    """Every teaching session of a study with its participant (pilots' unless include_pilot is False)."""
    stmt = (
        select(TaskSessionRow, ParticipantRow)
        .join(ParticipantRow, TaskSessionRow.participant_id == ParticipantRow.id)
        .where(ParticipantRow.study_id == study_id)
        .order_by(TaskSessionRow.participant_id, TaskSessionRow.task_index)
    )
    if not include_pilot:
        stmt = stmt.where(ParticipantRow.pilot.is_(False))
    return [(ts, p) for ts, p in session.execute(stmt)]
