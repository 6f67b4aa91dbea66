"""The study server on a real PostgreSQL: Debian's server binaries, a throwaway cluster per test module."""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tableteach.client import ParticipantClient, run_teacher

from ..conftest import REPO
from .conftest import ServerProcess, free_port, open_study, study_spec
from .test_e2e import _exports

pytestmark = pytest.mark.slow


def _postgres_bin() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(found[-1]).parent if found else None


def _as_server_user(args: list[str]) -> list[str]:
    """PostgreSQL refuses to run as root: use the package's postgres user then."""
    if os.geteuid() == 0:
        return ["runuser", "-u", "postgres", "--", *args]
    return args


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    """A fresh PostgreSQL cluster on 127.0.0.1 with trust auth; its SQLAlchemy URL."""
    bin_dir = _postgres_bin()
    if bin_dir is None or importlib_missing("psycopg"):
        if os.environ.get("CI"):
            pytest.fail("PostgreSQL tests need Debian's postgresql package and psycopg (scripts/test.sh installs both)")
        pytest.skip("Debian's postgresql package or psycopg is not installed")
    # Not under pytest's tmp tree: the postgres user cannot traverse root's private folders.
    folder = Path(tempfile.mkdtemp(prefix="tableteach-pg-"))
    if os.geteuid() == 0:
        shutil.chown(folder, user="postgres")
    data, port = folder / "data", free_port()
    subprocess.run(_as_server_user([str(bin_dir / "initdb"), "-D", str(data), "-A", "trust", "-U", "tableteach"]),
                   check=True, capture_output=True)
    options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1"
    subprocess.run(_as_server_user([str(bin_dir / "pg_ctl"), "-D", str(data), "-o", options, "-l",
                                    str(folder / "server.log"), "-w", "start"]), check=True, capture_output=True)
    try:
        yield f"postgresql+psycopg://tableteach@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run(_as_server_user([str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop"]),
                       capture_output=True)
        shutil.rmtree(folder, ignore_errors=True)


def importlib_missing(module: str) -> bool:
    """Whether a module cannot be imported."""
    import importlib.util

    return importlib.util.find_spec(module) is None


def test_migrations_apply_and_match_the_models_on_postgresql(postgres_url: str) -> None:
    env = {**os.environ, "TABLETEACH_DATABASE_URL": postgres_url}
    for command in (["upgrade", "head"], ["check"]):
        done = subprocess.run([sys.executable, "-m", "alembic", *command], cwd=REPO, env=env,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
    assert "No new upgrade operations detected" in done.stdout + done.stderr


def test_a_scripted_teacher_completes_a_session_and_survives_a_restart_on_postgresql(
    postgres_url: str, tmp_path: Path
) -> None:
    server = ServerProcess(tmp_path / "unused.db", database_url=postgres_url).start()
    try:
        banner = (tmp_path / f"unused.{server.port}.log").read_text()
        assert "(database postgresql+psycopg://" in banner  # really on PostgreSQL, not a SQLite fallback
        study_id = open_study(server.url, study_spec(["active"]))
        partial = run_teacher(server.url, study_id, ["task1"], seed=11, stop_after=6)
        before = ParticipantClient(server.url, token=partial.token).state()
        server.kill()  # a crash mid-session: everything acknowledged must be in PostgreSQL
        server = ServerProcess(tmp_path / "unused.db", database_url=postgres_url).start()
        api = ParticipantClient(server.url, token=partial.token)
        assert api.state() == before
        finished = run_teacher(server.url, study_id, ["task1"], seed=11, client=api)
        assert partial.completion_code is None and finished.completion_code
        exports = _exports(server.url, study_id)
        assert [e["kind"] for e in exports["events"]][-1] == "completed"
        assert exports["participants"][0]["stage"] == "done"
    finally:
        server.stop()
