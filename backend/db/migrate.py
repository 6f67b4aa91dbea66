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
