"""Engine and transactions: SQLite gets WAL, a busy timeout, foreign keys and BEGIN IMMEDIATE for writes.

Storage faults become TryLater (HTTP 503 with Retry-After), logged with their cause: a database another
process keeps locked past the busy timeout, and a SQLite file that was deleted or replaced under the
running server (whose writes would otherwise go to the deleted file and vanish at restart, while new
connections would create an empty database)."""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from ..errors import TryLater

log = logging.getLogger(__name__)

BUSY_TIMEOUT_MS = 5_000
RETRY_AFTER_SECONDS = 2
BUSY_MESSAGE = "The study's database is busy right now; please try again in a moment. Nothing you did was lost."
GONE_MESSAGE = ("The study's database is unavailable; please try again later. Nothing you did was lost. "
                "(The server's database file is missing or was replaced: restart the server.)")


SQLITE_BUSY_SNAPSHOT = 517  # a stale read snapshot cannot become a write: a lost race, not a busy database


def is_busy(exc: BaseException) -> bool:
    """Whether a database error means another connection holds the lock (SQLite 'database is locked/busy')."""
    orig = getattr(exc, "orig", exc)
    if getattr(orig, "sqlite_errorcode", None) == SQLITE_BUSY_SNAPSHOT:
        return False
    text_ = str(orig).lower()
    return isinstance(exc, OperationalError) and ("database is locked" in text_ or "database is busy" in text_
                                                  or "database table is locked" in text_)


def busy(exc: BaseException | None = None) -> TryLater:
    """The 503 for a busy database, logged with its cause."""
    log.warning("database busy, answering 503: %s", exc if exc is not None else "the write queue timed out")
    return TryLater(BUSY_MESSAGE, retry_after=RETRY_AFTER_SECONDS)


def _sqlite_pragmas(engine: Engine, busy_ms: int) -> None:
    """Pragmas on every connection; BEGIN IMMEDIATE so a writer never has to upgrade a stale read lock."""

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
        # pysqlite's own BEGIN handling is turned off so that the "begin" hook below decides.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute(f"PRAGMA busy_timeout={busy_ms}")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn) -> None:  # type: ignore[no-untyped-def]
        immediate = conn.get_execution_options().get("tableteach_write", False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")


def make_engine(url: str, busy_ms: int = BUSY_TIMEOUT_MS) -> Engine:
    """An engine for a database URL; SQLite files get their folder created and the pragmas above."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        if parsed.database and parsed.database != ":memory:":
            Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": busy_ms / 1000})
        _sqlite_pragmas(engine, busy_ms)
        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)


class _FileWatch:
    """The SQLite file the server opened: refuse to go on if it disappears or is replaced under it."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._identity: tuple[int, int] | None = None

    def check(self) -> None:
        """TryLater (logged) if the file is gone or is another file than the one first seen."""
        try:
            stat = os.stat(self.path)
        except FileNotFoundError:
            if self._identity is None:
                return  # not created yet (before the first migration): SQLite creates it
            log.error("database file %s was deleted under the running server; refusing requests until restart",
                      self.path)
            raise TryLater(GONE_MESSAGE, retry_after=60) from None
        identity = (stat.st_dev, stat.st_ino)
        if self._identity is None:
            self._identity = identity
        elif identity != self._identity:
            log.error("database file %s was replaced under the running server; refusing requests until restart",
                      self.path)
            raise TryLater(GONE_MESSAGE, retry_after=60)


class Database:
    """An engine with read and write transactions; callers commit through the yielded Session."""

    def __init__(self, url: str, *, busy_seconds: float = BUSY_TIMEOUT_MS / 1000) -> None:
        self.url = url
        self.busy_seconds = busy_seconds
        self.engine = make_engine(url, busy_ms=int(busy_seconds * 1000))
        self._read = sessionmaker(self.engine, expire_on_commit=False)
        self._write = sessionmaker(self.engine.execution_options(tableteach_write=True), expire_on_commit=False)
        # SQLite allows one writer; queueing writers of this process on a lock is fairer and faster than
        # SQLite's busy handler, which polls with sleeps of up to 100 ms. Other processes still meet busy_timeout.
        self._write_lock = threading.Lock() if self.engine.dialect.name == "sqlite" else None
        database = make_url(url).database
        sqlite_file = self.engine.dialect.name == "sqlite" and database and database != ":memory:"
        self._file = _FileWatch(Path(database)) if sqlite_file else None

    def check_file(self) -> None:
        """TryLater if the SQLite file under the server is gone or replaced (nothing to check elsewhere)."""
        if self._file is not None:
            self._file.check()

    @contextmanager
    def read(self) -> Iterator[Session]:
        """A read-only transaction (rolled back at the end)."""
        self.check_file()
        with self._busy_as_try_later(), self._read() as session:
            yield session
            session.rollback()

    @contextmanager
    def write(self) -> Iterator[Session]:
        """A write transaction; the caller commits, anything not committed is rolled back.

        A database locked by another process past the busy timeout, or a queue of this process's writers
        longer than that, is TryLater (503) rather than an endless wait."""
        self.check_file()
        if self._write_lock is not None and not self._write_lock.acquire(timeout=self.busy_seconds):
            raise busy()
        try:
            with self._busy_as_try_later(), self._write() as session:
                try:
                    yield session
                finally:
                    session.rollback()
        finally:
            if self._write_lock is not None:
                self._write_lock.release()

    @staticmethod
    @contextmanager
    def _busy_as_try_later() -> Iterator[None]:
        try:
            yield
        except OperationalError as exc:
            if is_busy(exc):
                raise busy(exc) from exc
            raise

    def health(self) -> None:
        """TryLater unless the database answers a query on its tables (the file is there and migrated)."""
        self.check_file()
        try:
            with self._read() as session:
                session.execute(text("SELECT 1 FROM studies LIMIT 1")).all()
        except OperationalError as exc:
            if is_busy(exc):
                raise busy(exc) from exc
            log.error("health check: the database does not answer: %s", exc)
            raise TryLater(GONE_MESSAGE, retry_after=60) from exc

    def dispose(self) -> None:
        """Close every pooled connection."""
        self.engine.dispose()
