"""Several hosts without a shared folder (TABLETEACH_RECORDING_STORE=database): two app processes on one PostgreSQL,
each with its own data folder; an execution worked out on one is served by the other, also once the first is dead,
and erasure removes its rows."""

from __future__ import annotations

import shutil
from pathlib import Path

import httpx
import pytest
from sqlalchemy import create_engine, make_url, select, text
from sqlalchemy.orm import Session

from tableteach.client import run_teacher
from tableteach.db import recording_rows
from tableteach.db.backup import create_backup, restore_backup
from tableteach.db.tables import ParticipantRow, RecordingFileRow

from tests.waiting import wait_until

from .conftest import EXPERIMENTER_TOKEN, ServerProcess, open_study, study_spec
from .test_postgres import postgres_url  # noqa: F401 - the module's throwaway PostgreSQL cluster
from .test_processes import MUJOCO_WAIT_SECONDS

pytestmark = pytest.mark.slow
EXP = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}


def _rows(url: str, uid: str) -> tuple[list[str], tuple[int, int, int]]:
    """The names of a participant's kept files, and (files, distinct bytes, bytes) kept in all."""
    engine = create_engine(url)
    try:
        with Session(engine) as s:
            names = sorted(s.scalars(select(RecordingFileRow.name).where(RecordingFileRow.participant_uid == uid)))
            return names, recording_rows.counts(s)
    finally:
        engine.dispose()


def _new_database(url: str, name: str) -> str:
    """Create an empty database on the same cluster; its URL."""
    engine = create_engine(url, isolation_level="AUTOCOMMIT")
    try:
        with engine.connect() as con:
            con.execute(text(f"CREATE DATABASE {name}"))
    finally:
        engine.dispose()
    return make_url(url).set(database=name).render_as_string(hide_password=False)


def _file(url: str, name: str) -> bytes | None:
    engine = create_engine(url)
    try:
        with Session(engine) as s:
            return recording_rows.file_bytes(s, name)
    finally:
        engine.dispose()


def _local(data_dir: Path, step: str) -> Path:
    """A host's own copy of a step's .viser file."""
    return data_dir / "recordings" / f"{step}.viser"


def _uid(url: str, participant_id: int) -> str:
    engine = create_engine(url)
    try:
        with Session(engine) as s:
            return s.scalars(select(ParticipantRow.uid).where(ParticipantRow.id == participant_id)).one()
    finally:
        engine.dispose()


def test_two_hosts_without_a_shared_folder_serve_each_others_recordings_and_erasure_removes_the_rows(
    postgres_url: str, tmp_path: Path  # noqa: F811 - the fixture imported above
) -> None:
    robot = {"TABLETEACH_ROBOT": "mujoco", "TABLETEACH_ROBOT_SPEED": "4", "TABLETEACH_RECORDING_STORE": "database"}
    a = ServerProcess(tmp_path / "a.db", database_url=postgres_url, TABLETEACH_DATA_DIR=str(tmp_path / "a-data"),
                      **robot).start()
    b = ServerProcess(tmp_path / "b.db", database_url=postgres_url, TABLETEACH_DATA_DIR=str(tmp_path / "b-data"),
                      **robot).start()
    try:
        study_id = open_study(a.url, study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1,
                                                n_tests=0))
        partial = run_teacher(a.url, study_id, ["task1"], seed=3, stop_after=3)  # consent, instructions, demo
        uid = _uid(postgres_url, partial.participant_id)
        headers = {"Authorization": f"Bearer {partial.token}"}
        started = httpx.post(f"{a.url}/api/v1/me/execution", headers=headers, timeout=60).json()
        assert started["execution"]["status"] == "running"
        # b hears of the plan through the database: a has worked the execution out and stored it with its files.
        wait_until(lambda: httpx.get(f"{b.url}/api/v1/me/robot", headers=headers, timeout=60).json()[
            "caption"].startswith("The robot is placing"), "a to work the execution out", timeout=MUJOCO_WAIT_SECONDS,
            interval=0.1)
        step = f"participant-{uid}/task-0/query-0"
        # Any process may run the job that works it out: the one whose folder has the file did.
        worker, other = (a, b) if _local(tmp_path / "a-data", step).is_file() else (b, a)
        folder = {a: tmp_path / "a-data", b: tmp_path / "b-data"}
        worked = _local(folder[worker], step).read_bytes()
        shutil.rmtree(folder[other] / "recordings", ignore_errors=True)  # the other host has no file of it at all

        path = f"/p/{partial.token}/motion/task-0/query-0.viser"
        served = httpx.get(f"{other.url}{path}", timeout=60)
        assert served.status_code == 200 and served.content == worked and len(worked) > 10_000
        assert _local(folder[other], step).read_bytes() == worked  # now in the other host's cache

        worker.kill()
        shutil.rmtree(folder[other] / "recordings")  # its cache lost too: the database still has the file
        again = httpx.get(f"{other.url}{path}", timeout=60)
        assert again.status_code == 200 and again.content == worked
        # The dashboard's replay reads the step's .npz and .json, which this host fetches from the database too.
        wait_until(lambda: httpx.get(f"{other.url}/api/v1/me", headers=headers, timeout=60).json()["execution"][
            "status"] == "finished", "the execution to finish", timeout=MUJOCO_WAIT_SECONDS)
        shutil.rmtree(folder[other] / "recordings")
        replay_url = f"{other.url}/api/v1/studies/{study_id}/participants/{partial.participant_id}/replays/0/query/0"
        # the page sees the motion end by its clock; the replay waits for the stored end (a job of the runtime)
        wait_until(lambda: httpx.get(replay_url, headers=EXP, timeout=60).status_code == 200,
                   "the execution's end to be stored", timeout=MUJOCO_WAIT_SECONDS)
        replay = httpx.get(replay_url, headers=EXP, timeout=60)
        assert replay.status_code == 200 and replay.json()["source"] == "recording", replay.text[:300]
        assert replay.json()["recording"]["poses"]

        names, (files, blobs, size) = _rows(postgres_url, uid)
        assert names == sorted([f"participant-{uid}/task-0/demonstration-0.json",
                                f"participant-{uid}/task-0/demonstration-0.npz",
                                f"{step}.json", f"{step}.npz", f"{step}.viser"]), names
        assert files == 5 and blobs == 5 and size > len(worked)
        print(f"kept for one participant: {files} files, {blobs} distinct, {size} bytes (.viser {len(worked)})")

        # A backup (pg_dump) holds the recordings kept in the database: restored into a new database, it has them.
        archive = tmp_path / "backup.tar.gz"
        (tmp_path / "empty-data").mkdir()
        create_backup(postgres_url, tmp_path / "empty-data", archive)
        restored_url = _new_database(postgres_url, "restored")
        restore_backup(archive, restored_url, tmp_path / "restored-data")
        assert _rows(restored_url, uid) == (names, (files, blobs, size))
        assert _file(restored_url, f"{step}.viser") == worked

        erased = httpx.delete(f"{other.url}/api/v1/studies/{study_id}/participants/{partial.participant_id}",
                              headers=EXP, timeout=60)
        assert erased.status_code == 204
        assert _rows(postgres_url, uid) == ([], (0, 0, 0))  # their rows and the bytes nobody else names
        assert not (folder[other] / "recordings" / f"participant-{uid}").exists()
        assert httpx.get(f"{other.url}{path}", timeout=60).status_code == 404
        # The killed host's own copies go when it runs again: its sweep finds the participant erased.
        mine = folder[worker] / "recordings" / f"participant-{uid}"
        assert mine.exists()
        again_worker = ServerProcess(tmp_path / "c.db", database_url=postgres_url,
                                     TABLETEACH_DATA_DIR=str(folder[worker]), **robot).start()
        try:
            wait_until(lambda: not mine.exists(), "the restarted host to remove its copies of the erased participant")
        finally:
            again_worker.stop()
    finally:
        a.stop()
        b.stop()
