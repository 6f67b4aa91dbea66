"""Backup and restore round trip: `tableteach backup` of a running server (MuJoCo robot, so there are recordings),
`tableteach restore` into a new database and data folder, and a server there answers every participant's state,
the exports and the recordings as before. On SQLite, and on PostgreSQL where Debian's packages are installed."""

from __future__ import annotations

from tests.states import comparable

import hashlib
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path
from typing import Any

import httpx
import pytest

from tableteach.client import ParticipantClient, run_teacher
from tableteach.db import throwaway_postgres

from .conftest import EXPERIMENTER_TOKEN, ServerProcess, open_study, study_spec
from .test_e2e import _exports

pytestmark = pytest.mark.slow
MUJOCO = {"TABLETEACH_ROBOT": "mujoco", "TABLETEACH_ROBOT_SPEED": "8"}


def _cli(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tableteach.cli", *args], env={**os.environ, **env},
                          capture_output=True, text=True, timeout=300)


def _files(folder: Path) -> dict[str, str]:
    """Every file under a folder with its SHA-256 (dev mode's key aside)."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and p.name != "dev-experimenter-token"}


def _served(server: ServerProcess, study_id: str, tokens: list[str], finished: str) -> dict[str, Any]:
    """What the server answers about the study: each participant's state, the finished one's recordings (the
    motion files the page plays), and the exports."""
    out: dict[str, Any] = {"exports": _exports(server.url, study_id), "states": {}, "recordings": {}}
    for token in tokens:
        out["states"][token] = comparable(ParticipantClient(server.url, token=token).state())
    for name in ("query-0", "test-0"):
        motion = httpx.get(f"{server.url}/p/{finished}/motion/task-0/{name}.viser", timeout=60)
        assert motion.status_code == 200 and len(motion.content) > 10_000, (name, motion.status_code)
        out["recordings"][name] = hashlib.sha256(motion.content).hexdigest()
    return out


def _round_trip(tmp_path: Path, database_url: str, restored_url: str) -> None:
    data = tmp_path / "data"
    server = ServerProcess(tmp_path / "study.db", database_url=database_url, TABLETEACH_DATA_DIR=str(data),
                           **MUJOCO).start()
    try:
        study_id = open_study(server.url, study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1,
                                                     n_tests=1))
        done = run_teacher(server.url, study_id, ["task1"], seed=5)
        partial = run_teacher(server.url, study_id, ["task1"], seed=6, stop_after=3)
        assert done.completion_code and partial.completion_code is None
        tokens = [t for t in (done.token, partial.token) if t]
        assert done.token is not None
        before = _served(server, study_id, tokens, done.token)
        archive = tmp_path / "backups" / "study.tar.gz"
        made = _cli("backup", "--out", str(archive), "--database-url", database_url, "--data-dir", str(data))
        assert made.returncode == 0, made.stderr  # while the server runs
        summary = json.loads(made.stdout)
        assert summary["files"] > 1 and summary["schema_revision"]
    finally:
        server.stop()

    with tarfile.open(archive) as tar:
        names = tar.getnames()
        manifest = json.loads(tar.extractfile("manifest.json").read())  # type: ignore[union-attr]
    assert all(not n.endswith((".pkl", ".pickle")) for n in names)
    assert {f["name"] for f in manifest["files"]} | {"manifest.json"} == set(names)

    new_data = tmp_path / "restored-data"
    restored = _cli("restore", str(archive), "--database-url", restored_url, "--data-dir", str(new_data))
    assert restored.returncode == 0, restored.stderr
    restored_files, original_files = _files(new_data), _files(data)
    assert restored_files == {f["name"].removeprefix("data/"): f["sha256"] for f in manifest["files"]
                              if f["name"].startswith("data/")}
    # Every file as it was (the robot may have planned the unfinished participant's next query after the backup).
    assert all(original_files[name] == digest for name, digest in restored_files.items())
    finished_uid = next(n.split("/")[1] for n in restored_files if n.endswith("test-0.npz"))
    assert {n for n in original_files if finished_uid in n} <= set(restored_files)
    again = _cli("restore", str(archive), "--database-url", restored_url, "--data-dir", str(new_data))
    assert again.returncode == 2 and "already has tables" in again.stderr and "--force" in again.stderr

    server = ServerProcess(tmp_path / "restored.db", database_url=restored_url, TABLETEACH_DATA_DIR=str(new_data),
                           **MUJOCO).start()
    try:
        after = _served(server, study_id, tokens, done.token)
        assert after == before
        # The restored session carries on.
        assert run_teacher(server.url, study_id, ["task1"], seed=6,
                           client=ParticipantClient(server.url, token=partial.token)).completion_code
    finally:
        server.stop()


def test_backup_while_serving_then_restore_on_sqlite_serves_everything_unchanged(tmp_path: Path) -> None:
    _round_trip(tmp_path, f"sqlite:///{tmp_path / 'study.db'}", f"sqlite:///{tmp_path / 'elsewhere' / 'study.db'}")


def test_backup_and_restore_on_postgresql(tmp_path: Path) -> None:
    if not throwaway_postgres.available():
        if os.environ.get("CI"):
            pytest.fail("PostgreSQL tests need Debian's postgresql package and psycopg (scripts/test.sh installs both)")
        pytest.skip("Debian's postgresql package or psycopg is not installed")
    from sqlalchemy import create_engine, text

    with throwaway_postgres.throwaway_postgres() as url:
        engine = create_engine(url, isolation_level="AUTOCOMMIT")
        with engine.connect() as connection:
            connection.execute(text("CREATE DATABASE restored"))
        engine.dispose()
        _round_trip(tmp_path, url, url.rsplit("/", 1)[0] + "/restored")


def _small_backup(tmp_path: Path) -> Path:
    from tableteach.db.migrate import upgrade_head

    url = f"sqlite:///{tmp_path / 'small.db'}"
    upgrade_head(url)
    (tmp_path / "data" / "recordings").mkdir(parents=True)
    (tmp_path / "data" / "recordings" / "x.json").write_text("{}")
    archive = tmp_path / "small.tar.gz"
    made = _cli("backup", "--out", str(archive), "--database-url", url, "--data-dir", str(tmp_path / "data"))
    assert made.returncode == 0, made.stderr
    return archive


def test_a_damaged_backup_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    archive = _small_backup(tmp_path)
    damaged = tmp_path / "damaged.tar.gz"
    with tarfile.open(archive) as src, tarfile.open(damaged, "w:gz") as dst:
        for info in src:
            data = src.extractfile(info).read()  # type: ignore[union-attr]
            if info.name == "data/recordings/x.json":
                data = b"{1}"
                info.size = len(data)
            import io

            dst.addfile(info, io.BytesIO(data))
    target = tmp_path / "target.db"
    out = _cli("restore", str(damaged), "--database-url", f"sqlite:///{target}", "--data-dir", str(tmp_path / "t"))
    assert out.returncode == 2 and "damaged" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert not target.exists() and not (tmp_path / "t").exists()
    garbage = tmp_path / "garbage.tar.gz"
    garbage.write_bytes(b"not a backup")
    out = _cli("restore", str(garbage), "--database-url", f"sqlite:///{target}", "--data-dir", str(tmp_path / "t"))
    assert out.returncode == 2 and "not a readable TableTeach backup" in out.stderr


def test_backup_of_a_database_with_no_schema_says_so(tmp_path: Path) -> None:
    out = _cli("backup", "--out", str(tmp_path / "b.tar.gz"), "--database-url", f"sqlite:///{tmp_path / 'none.db'}",
               TABLETEACH_EXPERIMENTER_TOKEN=EXPERIMENTER_TOKEN)
    assert out.returncode == 2 and "has no schema" in out.stderr
    assert not (tmp_path / "b.tar.gz").exists()
