"""Storage: migrations match the tables, SQLite pragmas, optimistic locking and idempotency constraints."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import text

from tableteach.db import repository as repo
from tableteach.db.engine import Database
from tableteach.db.migrate import REPO_ROOT, upgrade_head

ALEMBIC = [sys.executable, "-m", "alembic", "-c", str(REPO_ROOT / "alembic.ini")]


def test_alembic_upgrade_head_then_check_on_a_fresh_sqlite_file(tmp_path: Path) -> None:
    env = {**os.environ, "TABLETEACH_DATABASE_URL": f"sqlite:///{tmp_path / 'fresh.db'}"}
    up = subprocess.run(ALEMBIC + ["upgrade", "head"], env=env, capture_output=True, text=True, cwd=tmp_path)
    assert up.returncode == 0, up.stderr
    check = subprocess.run(ALEMBIC + ["check"], env=env, capture_output=True, text=True, cwd=tmp_path)
    assert check.returncode == 0, check.stdout + check.stderr
    assert "No new upgrade operations detected" in check.stdout + check.stderr
    with sqlite3.connect(tmp_path / "fresh.db") as con:
        tables = {r[0] for r in con.execute("select name from sqlite_master where type = 'table'")}
    assert {"studies", "participants", "task_sessions", "events", "alembic_version"} <= tables


def test_programmatic_upgrade_is_idempotent_and_pragmas_are_on(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'sub' / 'app.db'}"
    upgrade_head(url)
    upgrade_head(url)
    db = Database(url)
    with db.read() as s:
        assert s.execute(text("pragma journal_mode")).scalar() == "wal"
        assert s.execute(text("pragma foreign_keys")).scalar() == 1
        assert s.execute(text("pragma busy_timeout")).scalar() >= 5000
    db.dispose()


@pytest.fixture
def db(tmp_path: Path) -> Database:
    url = f"sqlite:///{tmp_path / 'repo.db'}"
    upgrade_head(url)
    database = Database(url)
    yield database
    database.dispose()


def _participant(db: Database) -> int:
    with db.write() as s:
        repo.add_study(s, values=dict(
            id="s1", name="s", tasks=[{"key": "task1"}], conditions=["active"], assignment="random", n_practice=1,
            n_demonstrations=2, n_queries=3, n_tests=3, prior="chains-2020-sat", criterion="min-regret",
            questionnaire=[], consent_text="c", consent_version="1", status="open"))
        p = repo.add_participant(s, values=dict(token="tok", study_id="s1", condition="active", seed=1, n_events=0))
        repo.commit(s)
        return p.id


def test_two_writers_of_one_participant_cannot_both_win(db: Database) -> None:
    pid = _participant(db)
    # Two sessions load version n; the first to commit wins, the second gets WriteConflict, not a lost update.
    a_ctx, b_ctx = db._read(), db._read()  # deferred transactions to set up the race without BEGIN IMMEDIATE
    with a_ctx as a, b_ctx as b:
        pa = repo.get_participant_and_study(a, token="tok")[0]
        pb = repo.get_participant_and_study(b, token="tok")[0]
        repo.append_event(a, participant=pa, kind="x", payload={}, app_version="t")
        repo.commit(a)
        with pytest.raises(repo.WriteConflict):  # when it writes its event (SQLite) or commits
            repo.append_event(b, participant=pb, kind="y", payload={}, app_version="t")
            repo.commit(b)
    with db.read() as s:
        p = repo.get_participant_and_study(s, token="tok")[0]
        assert p.n_events == 1 and p.id == pid


def test_a_client_event_id_is_unique_per_participant(db: Database) -> None:
    _participant(db)
    with db.write() as s:
        p = repo.get_participant_and_study(s, token="tok")[0]
        repo.append_event(s, participant=p, kind="x", payload={}, app_version="t", client_event_id="k")
        repo.commit(s)
    with db.write() as s:
        p, _, earlier = repo.get_participant_for_request(s, token="tok", client_event_id="k")
        assert earlier is not None and earlier.kind == "x"
        # Bypass the service's check: the database itself refuses a second event with the same key.
        p.n_events += 5
        with pytest.raises(repo.WriteConflict):
            repo.append_event(s, participant=p, kind="y", payload={}, app_version="t", client_event_id="k")


def test_deleting_a_study_cascades_to_its_participants(db: Database) -> None:
    _participant(db)
    with db.write() as s:
        s.execute(text("delete from studies where id = 's1'"))
        repo.commit(s)
    with db.read() as s:
        assert repo.get_participant_and_study(s, token="tok") is None
