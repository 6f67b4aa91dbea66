"""The study server on a real PostgreSQL: Debian's server binaries, a throwaway cluster per test module."""

from __future__ import annotations

from tests.states import comparable

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tableteach.client import ParticipantClient, run_teacher
from tableteach.db import throwaway_postgres

from ..conftest import REPO
from .conftest import ServerProcess, open_study, study_spec
from .test_e2e import _exports

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    """A fresh PostgreSQL cluster on 127.0.0.1 with trust auth; its SQLAlchemy URL."""
    if not throwaway_postgres.available():
        if os.environ.get("CI"):
            pytest.fail("PostgreSQL tests need Debian's postgresql package and psycopg (scripts/test.sh installs both)")
        pytest.skip("Debian's postgresql package or psycopg is not installed")
    with throwaway_postgres.throwaway_postgres() as url:
        yield url


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
        assert comparable(api.state()) == comparable(before)
        finished = run_teacher(server.url, study_id, ["task1"], seed=11, client=api)
        assert partial.completion_code is None and finished.completion_code
        exports = _exports(server.url, study_id)
        assert [e["kind"] for e in exports["events"]][-1] == "completed"
        assert exports["participants"][0]["stage"] == "done"
    finally:
        server.stop()
