"""Entity tags of a participant's state: a digest of the versions of every row the state is built from (the
participant, the study, the current task's session; each bumped by every update) and of the one thing that changes
by the clock alone, whether a running execution has reached its stored end. GET /me's ETag, the state's own `etag`
field and each change event carry the same tag, so a page holding it knows when there is nothing new to read."""

from __future__ import annotations

import hashlib
from typing import Any

from ..db.repository import PollRow
from ..db.tables import ParticipantRow, StudyRow, TaskSessionRow
from . import executions


def digest_tag(*parts: object) -> str:
    """A weak entity tag of these parts."""
    digest = hashlib.blake2b("|".join(map(str, parts)).encode(), digest_size=12).hexdigest()
    return f'W/"{digest}"'


def state_tag(row: PollRow) -> str:
    """The entity tag of the state built from these row versions (now)."""
    ex = row.execution
    finished = bool(ex and ex.get("status") == "running" and executions.progress(ex).finished)
    updated = row.study_updated_at.isoformat() if row.study_updated_at else ""
    return digest_tag("state", row.participant_id, row.participant_version, updated, row.task_version, finished)


def state_tag_of(participant: ParticipantRow, study: StudyRow, session: TaskSessionRow | None) -> str:
    """The same tag from the rows themselves (session: the current task's, in the task stage)."""
    in_task = participant.stage == "task" and session is not None
    execution: dict[str, Any] | None = session.execution if in_task and session is not None else None
    return state_tag(PollRow(participant.id, participant.version, participant.stage, participant.task_index,
                             study.updated_at, session.version if in_task and session is not None else None,
                             execution))
