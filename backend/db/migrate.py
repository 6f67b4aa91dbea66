"""Run the alembic migrations programmatically (alembic.ini and alembic/ at the repository root)."""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config

REPO_ROOT = Path(__file__).resolve().parents[2]


def _root() -> Path:
    """The folder holding alembic.ini: the source checkout, else the current directory."""
    for folder in (REPO_ROOT, Path.cwd()):
        if (folder / "alembic.ini").exists() and (folder / "alembic").is_dir():
            return folder
    raise ValueError(f"alembic.ini and alembic/ not found in {REPO_ROOT} or {Path.cwd()}: "
                     "run from a source checkout (or an editable install)")


def alembic_config(database_url: str) -> Config:
    """An alembic Config for the repository's migrations, pointed at a database URL."""
    root = _root()
    config = Config(str(root / "alembic.ini"))
    config.set_main_option("script_location", str(root / "alembic"))
    # Read by alembic/env.py; the URL is never written to alembic.ini.
    config.attributes["database_url"] = database_url
    return config


def upgrade_head(database_url: str) -> None:
    """Bring a database to the newest schema (creating it if empty)."""
    command.upgrade(alembic_config(database_url), "head")


def head_revision() -> str:
    """The newest schema revision this version of the server knows."""
    from alembic.script import ScriptDirectory

    head = ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head()
    if head is None:
        raise ValueError("the alembic/ folder has no migrations")
    return head


def known_revisions() -> list[str]:
    """Every schema revision this version knows, oldest first."""
    from alembic.script import ScriptDirectory

    script = ScriptDirectory.from_config(alembic_config("sqlite://"))
    return [rev.revision for rev in reversed(list(script.walk_revisions()))]


def current_revision(database_url: str) -> str | None:
    """The database's schema revision (None: no schema yet); a missing SQLite file is not created."""
    from sqlalchemy import create_engine, inspect, pool, text
    from sqlalchemy.engine import make_url

    url = make_url(database_url)
    if url.get_backend_name() == "sqlite" and url.database and url.database != ":memory:":
        if not Path(url.database).exists():
            return None
    engine = create_engine(url, poolclass=pool.NullPool)
    try:
        with engine.connect() as connection:
            if not inspect(connection).has_table("alembic_version"):
                return None
            return connection.execute(text("SELECT version_num FROM alembic_version")).scalar()
    finally:
        engine.dispose()


def schema_problem(database_url: str, shown_url: str) -> str | None:
    """Why the server cannot serve this database as it is (no schema, an older one, one it does not know), with
    the command that fixes it; None when the database is at the newest revision."""
    head, current = head_revision(), current_revision(database_url)
    if current == head:
        return None
    migrate = f"tableteach migrate --database-url '{shown_url}'"
    if current is None:
        return (f"the database {shown_url} has no schema yet (this server needs revision {head}): "
                f"run `{migrate}` first, or `tableteach serve --migrate`")
    if current in known_revisions():
        return (f"the database {shown_url} is at schema revision {current}, this server needs {head}: back it up "
                f"(`tableteach backup --out FILE`), then run `{migrate}`")
    return (f"the database {shown_url} is at schema revision {current}, which this server version does not know "
            f"(its newest is {head}): it was migrated by a newer version; run that version or restore a backup")
