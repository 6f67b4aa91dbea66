"""Recordings every host reaches (TABLETEACH_RECORDING_STORE=database): the finished files of each step are kept in
the database (tableteach.db.recording_rows: bytes by SHA-256, so a motion participants share is kept once), and each
host's data folder is a cache of them, filled from the database when a file this host must read is missing.

The robot still writes its files into the local folder; the services add a step's finished files to the database in
the transaction that stores the robot's result (services.background.work_out), or right after a demonstration is
saved. Erasure forgets the participant's files in its own transaction (repository.delete_participant_data), then
this store removes the local copies and the bytes nobody names any more.
"""

from __future__ import annotations

import logging
import os
import shutil
import threading
from pathlib import Path
from typing import Any

from ..recording_store import (FOLDER, SUFFIXES, VISER_SUFFIX, FileRecordingStore, RecordingFile, RecordingId,
                               RecordingStore, check_uid)
from ..scenes.spec import SceneSpec
from . import recording_rows
from .engine import Database

log = logging.getLogger(__name__)


def _is_uid(text: str) -> bool:
    try:
        check_uid(text)
    except ValueError:
        return False
    return True


class DatabaseRecordingStore:
    """The recording store of several hosts: `local` (this host's files, with the scene) as a cache of the database."""

    def __init__(self, local: RecordingStore, db: Database, data_dir: Path | str) -> None:
        self.local = local
        self.db = db
        self.data_dir = Path(data_dir)

    def _path(self, rid: RecordingId, suffix: str) -> Path:
        return (self.data_dir / FOLDER / rid.name).with_suffix(suffix)

    def playable(self, rid: RecordingId) -> Path:
        """Where this host keeps (or will keep) the step's .viser file."""
        return self.local.playable(rid)

    def fetch(self, rid: RecordingId, suffix: str) -> bool:
        """Whether the step's file with this suffix is in the local folder, copied there from the database if it was
        missing; False while the database has none."""
        path = self._path(rid, suffix)
        if path.is_file():
            return True
        with self.db.read() as s:
            data = recording_rows.file_bytes(s, f"{rid.name}{suffix}")
        if data is None:
            return False
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
        return True

    def ready(self, rid: RecordingId) -> bool:
        """Whether the step's .viser file is in the local folder (fetched from the database if need be)."""
        return self.fetch(rid, VISER_SUFFIX)

    def finished(self, rid: RecordingId) -> list[RecordingFile]:
        """The step's files in the local folder (its .npz and .json, and its .viser for an execution)."""
        out = []
        for suffix in SUFFIXES:
            path = self._path(rid, suffix)
            try:
                out.append(RecordingFile(f"{rid.name}{suffix}", rid.participant_uid, path.read_bytes()))
            except FileNotFoundError:
                continue
        return out

    def delete_participant(self, participant_uid: str) -> int:
        """Remove the participant's local files, their files' rows (again, if erasure did) and the bytes nobody
        names any more; the number of local files and rows removed."""
        removed = self.local.delete_participant(check_uid(participant_uid))
        with self.db.write() as s:
            removed += recording_rows.delete_participant_files(s, participant_uid)
            s.commit()
        return removed + self.sweep()

    def sweep(self) -> int:
        """Delete the bytes no file names any more; how many (a sweep that meets a file being added leaves them)."""
        try:
            with self.db.write() as s:
                swept = recording_rows.sweep_blobs(s)
                s.commit()
            return swept
        except Exception:  # noqa: BLE001 - a file added meanwhile names them: the next sweep takes what is left
            log.warning("could not sweep unnamed recording bytes now; the next erasure sweeps them", exc_info=True)
            return 0

    def cached_uids(self) -> list[str]:
        """The participants with a folder in this host's cache."""
        root = self.data_dir / FOLDER
        if not root.is_dir():
            return []
        return sorted(p.name.removeprefix("participant-") for p in root.glob("participant-*")
                      if _is_uid(p.name.removeprefix("participant-")))

    def forget_cached(self, participant_uids: list[str]) -> int:
        """Remove this host's copies of these participants' files (erased on another host); how many folders."""
        removed = 0
        for uid in participant_uids:
            folder = self.data_dir / FOLDER / f"participant-{check_uid(uid)}"
            if folder.exists():
                shutil.rmtree(folder, ignore_errors=True)
                removed += 1
        if removed:
            FileRecordingStore(self.data_dir).sweep_shared()
        return removed

    def layout(self, scene: SceneSpec | None = None) -> dict[str, Any]:
        """The scene seen from above (the local store's)."""
        return self.local.layout(scene)

    def top_view(self, rid: RecordingId, scene: SceneSpec | None = None) -> dict[str, Any] | None:
        """A recorded step from above, its .npz and .json fetched from the database if this host lacks them."""
        if not (self.fetch(rid, ".npz") and self.fetch(rid, ".json")):
            return None
        return self.local.top_view(rid, scene)


def make_store(kind: str, local: RecordingStore, db: Database, data_dir: Path | str) -> RecordingStore:
    """The recording store TABLETEACH_RECORDING_STORE names: 'files' (`local` alone) or 'database'."""
    if kind == "files":
        return local
    if kind == "database":
        return DatabaseRecordingStore(local, db, data_dir)
    raise ValueError(f"TABLETEACH_RECORDING_STORE is {kind!r}: expected 'files' (the data folder; one host, or a "
                     "folder every host shares) or 'database' (kept in the database, each host's folder a cache)")


__all__ = ["DatabaseRecordingStore", "FileRecordingStore", "make_store"]
