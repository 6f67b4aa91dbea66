"""Change notices per participant: a counter bumped after every change of their state or robot, awaited by the page.

LocalNotifier works inside one process (threads publish, asyncio tasks wait); tableteach.db.pg_notify's
PgNotifier carries the same notices between processes (PostgreSQL LISTEN/NOTIFY). The server-sent events
at /p/{token}/events wait on the one in use (Context.notifier).
"""

from __future__ import annotations

from sqlalchemy.engine import make_url

from ..notices import LocalNotifier

__all__ = ["LocalNotifier", "make_notifier", "participant_of_key"]


def participant_of_key(key: str) -> int | None:
    """The participant id of a robot table key "<participant id>/<task index>", or None for another form."""
    head, _, _ = key.partition("/")
    return int(head) if head.isdigit() else None


def make_notifier(database_url: str) -> LocalNotifier:
    """The notifier for a database: LISTEN/NOTIFY on PostgreSQL (several processes), in-process otherwise."""
    if make_url(database_url).get_backend_name() == "postgresql":
        from ..db.pg_notify import PgNotifier  # imports psycopg, which only PostgreSQL needs

        return PgNotifier(database_url)
    return LocalNotifier()
