"""The database recording store on SQLite: bytes kept once by digest, a host's folder filled from the database,
erasure sweeping only the bytes nobody names, and a bad setting refused with its name."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from tableteach.config import Settings
from tableteach.db import recording_rows
from tableteach.db.engine import Database
from tableteach.db.migrate import upgrade_head
from tableteach.db.shared_recordings import DatabaseRecordingStore, make_store
from tableteach.recording_store import FileRecordingStore, RecordingFile, RecordingId

ANN, BOB = "a" * 32, "b" * 32


def _keep(db: Database, files: list[RecordingFile]) -> int:
    with db.write() as s:
        added = recording_rows.add_files(s, files)
        s.commit()
    return added


def _counts(db: Database) -> tuple[int, int, int]:
    with db.read() as s:
        return recording_rows.counts(s)


def test_shared_bytes_are_kept_once_fetched_into_another_folder_and_swept_when_nobody_names_them(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    upgrade_head(url)
    db = Database(url)
    here = DatabaseRecordingStore(FileRecordingStore(tmp_path / "here"), db, tmp_path / "here")
    there = DatabaseRecordingStore(FileRecordingStore(tmp_path / "there"), db, tmp_path / "there")
    ann, bob = RecordingId(ANN, 0, "query", 0), RecordingId(BOB, 0, "query", 0)
    motion = b"the same motion" * 1000
    for rid in (ann, bob):  # as a robot writes them on this host: the shared motion, a .json of one's own
        here.playable(rid).parent.mkdir(parents=True, exist_ok=True)
        here.playable(rid).write_bytes(motion)
        here.playable(rid).with_suffix(".json").write_text(rid.participant_uid)
        assert [f.name.rsplit(".", 1)[1] for f in here.finished(rid)] == ["json", "viser"]

    assert _keep(db, here.finished(ann)) == len(motion) + 32
    assert _keep(db, here.finished(bob)) == 32  # the motion's bytes are there already
    assert _counts(db) == (4, 3, len(motion) + 64)

    assert not there.playable(ann).exists()
    assert there.ready(ann) and there.playable(ann).read_bytes() == motion  # filled from the database
    assert not there.ready(RecordingId(ANN, 0, "query", 1))  # nothing kept of that step

    # The local copy, the two rows and Ann's .json bytes; the motion's bytes stay, Bob's file names them.
    assert there.delete_participant(ANN) == 1 + 2 + 1
    assert not there.playable(ann).exists() and _counts(db) == (2, 2, len(motion) + 32)
    assert there.delete_participant(BOB) == 2 + 2  # no local copy of Bob's here: the rows, then the two blobs
    assert _counts(db) == (0, 0, 0)
    db.dispose()


def test_the_recording_store_setting_names_the_problem() -> None:
    assert Settings(recording_store="database").recording_store == "database"
    assert Settings().recording_store == "files"
    with pytest.raises(ValidationError, match="TABLETEACH_RECORDING_STORE is 's3://bucket': expected 'files'"):
        Settings(recording_store="s3://bucket")
    with pytest.raises(ValueError, match="TABLETEACH_RECORDING_STORE is 'nfs'"):
        make_store("nfs", FileRecordingStore("x"), Database("sqlite://"), "x")
