"""Upgrades: a database at every earlier schema revision, holding study data, migrates to head with its rows kept,
and the server then serves them; `serve` refuses a database that is not at head, saying how to migrate."""

from __future__ import annotations

from tests.states import comparable

import os
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from alembic import command

from tableteach.db.migrate import alembic_config, current_revision, head_revision, known_revisions, upgrade_head

from ..web.conftest import EXPERIMENTER_TOKEN, in_process_app
from ..web.helpers import EXP, bearer, demonstrate, join, make_study, to_teaching

Rows = dict[str, list[dict[str, Any]]]


def _tables(path: Path) -> list[str]:
    with sqlite3.connect(path) as con:
        return [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table' "
                                          "AND name NOT IN ('alembic_version', 'sqlite_sequence') ORDER BY name")]


def _columns(path: Path, table: str) -> list[str]:
    with sqlite3.connect(path) as con:
        return [r[1] for r in con.execute(f"PRAGMA table_info({table})")]


def _dump(path: Path) -> Rows:
    """Every row of every table, as the raw values SQLite stores."""
    with sqlite3.connect(path) as con:
        con.row_factory = sqlite3.Row
        return {table: [dict(r) for r in con.execute(f"SELECT * FROM {table} ORDER BY rowid")]
                for table in _tables(path)}


def _insert(path: Path, rows: Rows) -> dict[str, list[str]]:
    """Insert the rows with raw SQL, each only with the columns its table has at this revision; those columns."""
    kept: dict[str, list[str]] = {}
    order = ["studies", "participants", "task_sessions", "events", "erasures"]
    with sqlite3.connect(path) as con:
        present = set(_tables(path))
        for table in [t for t in order if t in present]:
            columns = _columns(path, table)
            kept[table] = columns
            for row in rows[table]:
                names = [c for c in columns if c in row]
                con.execute(f"INSERT INTO {table} ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})",
                            [row[c] for c in names])
    return kept


@pytest.fixture(scope="module")
def head_data(tmp_path_factory: pytest.TempPathFactory) -> tuple[Rows, dict[str, Any]]:
    """Representative rows made by the server at head: a finished demonstration, a participant at consent, an
    erased participant (an erasure audit row); and what the server answered for each participant then."""
    folder = tmp_path_factory.mktemp("head")
    with in_process_app(folder) as client:
        study_id = make_study(client)
        token, _ = to_teaching(client, study_id)
        demonstrate(client, token, ["dinner_plate"])
        demonstrate(client, token, ["dinner_plate", "fork", "knife"])
        waiting, _ = join(client, study_id, prolific_pid="p-waiting")
        erased, _ = join(client, study_id, prolific_pid="p-erased")
        erased_id = client.get("/api/v1/me", headers=bearer(erased)).json()["participant_id"]
        assert client.delete(f"/api/v1/studies/{study_id}/participants/{erased_id}", headers=EXP).status_code == 204
        served = {
            "study_id": study_id,
            "states": {t: client.get("/api/v1/me", headers=bearer(t)).json() for t in (token, waiting)},
            "participants_csv": client.get(f"/api/v1/studies/{study_id}/exports/participants.csv", headers=EXP).text,
            "steps_csv": client.get(f"/api/v1/studies/{study_id}/exports/steps.csv", headers=EXP).text,
        }
        client.ctx.db.dispose()
    rows = _dump(folder / "app.db")
    assert rows["participants"] and rows["events"] and rows["task_sessions"] and rows["erasures"]
    return rows, served


@pytest.mark.parametrize("revision", known_revisions()[:-1])
def test_a_database_at_an_earlier_revision_with_data_migrates_to_head_and_is_served(
    revision: str, head_data: tuple[Rows, dict[str, Any]], tmp_path: Path
) -> None:
    rows, served = head_data
    url = f"sqlite:///{tmp_path / 'app.db'}"
    command.upgrade(alembic_config(url), revision)
    assert current_revision(url) == revision
    kept = _insert(tmp_path / "app.db", rows)

    upgrade_head(url)
    assert current_revision(url) == head_revision()
    after = _dump(tmp_path / "app.db")
    for table, columns in kept.items():
        assert [{c: r[c] for c in columns} for r in after[table]] == [{c: r[c] for c in columns} for r in rows[table]]
    assert len({r["uid"] for r in after["participants"]}) == len(after["participants"])  # filled in, unique

    # Move the migrated file where in_process_app looks, then serve it.
    served_dir = tmp_path / "served"
    served_dir.mkdir()
    (tmp_path / "app.db").rename(served_dir / "app.db")
    with in_process_app(served_dir) as client:
        for token, state in served["states"].items():
            answer = client.get("/api/v1/me", headers=bearer(token))
            assert answer.status_code == 200, answer.text
            assert comparable(answer.json(), versions=False) == comparable(state, versions=False)
        study = client.get(f"/api/v1/studies/{served['study_id']}", headers=EXP)
        assert study.status_code == 200 and study.json()["id"] == served["study_id"]
        for name in ("participants", "steps"):
            export = client.get(f"/api/v1/studies/{served['study_id']}/exports/{name}.csv", headers=EXP)
            assert export.status_code == 200
            assert export.text.splitlines()[0] == served[f"{name}_csv"].splitlines()[0]
            assert len(export.text.splitlines()) == len(served[f"{name}_csv"].splitlines())
        # The session carries on after the upgrade.
        token = next(iter(served["states"]))
        assert client.post("/api/v1/me/demonstration/finish", headers=bearer(token)).status_code in (200, 409)


def _serve(url: str, tmp_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": EXPERIMENTER_TOKEN, "TABLETEACH_ROBOT": "trace",
           "TABLETEACH_DATA_DIR": str(tmp_path / "data")}
    return subprocess.run([sys.executable, "-m", "tableteach.cli", "serve", "--port", "0", "--database-url", url,
                           *extra], env=env, capture_output=True, text=True, timeout=120)


def test_serve_refuses_an_empty_or_older_database_in_one_line_naming_the_migrate_command(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'old.db'}"
    empty = _serve(url, tmp_path)
    assert empty.returncode == 2 and len(empty.stderr.strip().splitlines()) == 1, empty.stderr
    assert "has no schema yet" in empty.stderr and "tableteach migrate --database-url" in empty.stderr
    assert not (tmp_path / "old.db").exists()  # looking did not create it

    older = known_revisions()[-2]
    command.upgrade(alembic_config(url), older)
    behind = _serve(url, tmp_path)
    assert behind.returncode == 2 and len(behind.stderr.strip().splitlines()) == 1, behind.stderr
    assert f"at schema revision {older}, this server needs {head_revision()}" in behind.stderr
    assert "tableteach migrate" in behind.stderr and "backup" in behind.stderr


def test_serve_refuses_a_database_migrated_by_a_newer_version(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'new.db'}"
    upgrade_head(url)
    with sqlite3.connect(tmp_path / "new.db") as con:
        con.execute("UPDATE alembic_version SET version_num = '9999_from_the_future'")
    out = _serve(url, tmp_path)
    assert out.returncode == 2 and "9999_from_the_future" in out.stderr and "newer version" in out.stderr


def test_the_migrate_command_reports_the_revisions(tmp_path: Path) -> None:
    import json

    url = f"sqlite:///{tmp_path / 'm.db'}"
    command.upgrade(alembic_config(url), known_revisions()[0])
    out = subprocess.run([sys.executable, "-m", "tableteach.cli", "migrate", "--database-url", url],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == {"database": url, "from_revision": known_revisions()[0],
                                      "to_revision": head_revision()}


def test_healthz_names_the_app_version(tmp_path: Path) -> None:
    from importlib.metadata import version

    with in_process_app(tmp_path) as client:
        assert client.get("/healthz").json() == {"status": "ok", "version": version("tableteach")}
