"""The recording tables' queries (TABLETEACH_RECORDING_STORE=database): file bytes kept once by their SHA-256, and
each participant's files naming them. Like the other repository functions these flush but never commit.

A file added while an erasure sweeps the bytes it names fails on the foreign key (its job is tried again and adds
the bytes anew); a sweep that fails so leaves the bytes for the next sweep.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sqlalchemy import delete, exists, func, select
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session

from ..recording_store import RecordingFile
from .tables import RecordingBlobRow, RecordingFileRow, utcnow


def add_files(session: Session, files: Iterable[RecordingFile]) -> int:
    """Keep these files (bytes not kept yet are added, a file of the same name is replaced); bytes added."""
    files = list(files)
    if not files:
        return 0
    digests = {f.digest for f in files}
    have = set(session.scalars(select(RecordingBlobRow.digest).where(RecordingBlobRow.digest.in_(digests))))
    added = 0
    for f in files:
        digest = f.digest
        if digest not in have:  # another process may add the same bytes at this moment: theirs are the same
            session.execute(_insert_blob(session).values(digest=digest, size=len(f.data), data=f.data,
                                                         created_at=utcnow()).on_conflict_do_nothing())
            have.add(digest)
            added += len(f.data)
    for f in files:
        row = session.get(RecordingFileRow, f.name)
        if row is None:
            session.add(RecordingFileRow(name=f.name, participant_uid=f.participant_uid, digest=f.digest))
        else:
            row.digest = f.digest
    session.flush()
    return added


def _insert_blob(session: Session) -> Any:
    """INSERT into recording_blobs in the session's dialect (both have ON CONFLICT DO NOTHING)."""
    if session.get_bind().dialect.name == "postgresql":
        return postgresql.insert(RecordingBlobRow)
    return sqlite.insert(RecordingBlobRow)


def file_bytes(session: Session, name: str) -> bytes | None:
    """The bytes of a kept file, or None if no file of that name is kept."""
    return session.scalar(select(RecordingBlobRow.data).join(
        RecordingFileRow, RecordingFileRow.digest == RecordingBlobRow.digest).where(RecordingFileRow.name == name))


def delete_participant_files(session: Session, participant_uid: str) -> int:
    """Forget every file of one participant (their bytes stay until swept); how many."""
    result = session.execute(delete(RecordingFileRow).where(RecordingFileRow.participant_uid == participant_uid))
    return int(result.rowcount or 0)  # type: ignore[attr-defined]


def sweep_blobs(session: Session) -> int:
    """Delete the bytes no file names any more (motion nobody shares now); how many."""
    named = exists().where(RecordingFileRow.digest == RecordingBlobRow.digest)
    result = session.execute(delete(RecordingBlobRow).where(~named))
    return int(result.rowcount or 0)  # type: ignore[attr-defined]


def counts(session: Session, participant_uid: str | None = None) -> tuple[int, int, int]:
    """Files kept (of one participant, if given), distinct bytes kept, and their total size in bytes."""
    files = select(func.count()).select_from(RecordingFileRow)
    if participant_uid is not None:
        files = files.where(RecordingFileRow.participant_uid == participant_uid)
    blobs = session.execute(select(func.count(), func.coalesce(func.sum(RecordingBlobRow.size), 0))
                            .select_from(RecordingBlobRow)).one()
    return int(session.scalar(files) or 0), int(blobs[0]), int(blobs[1])
