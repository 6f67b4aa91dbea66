"""State-change notices across app processes with PostgreSQL LISTEN/NOTIFY: publish() wakes this process's
waiters at once and sends NOTIFY; a listener thread hands other processes' notices to the local notifier.

Payloads are "<process id>:<participant id>" (two integers, parsed strictly; nothing else crosses processes).
A lost listener connection is re-opened; pages also refresh on their own, so a notice missed meanwhile only
delays an update.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time

import psycopg
from sqlalchemy.engine import make_url

from ..notices import LocalNotifier

log = logging.getLogger(__name__)
CHANNEL = "tableteach_state"
RECONNECT_SECONDS = 1.0


def libpq_url(database_url: str) -> str:
    """The libpq connection string of a SQLAlchemy PostgreSQL URL (ValueError for any other database)."""
    url = make_url(database_url)
    if url.get_backend_name() != "postgresql":
        raise ValueError(f"{url.drivername} is not PostgreSQL: LISTEN/NOTIFY needs a postgresql+psycopg:// URL")
    return url.set(drivername="postgresql").render_as_string(hide_password=False)


class PgNotifier(LocalNotifier):
    """A LocalNotifier whose notices also reach (and come from) every other process on the same database."""

    def __init__(self, database_url: str) -> None:
        super().__init__()
        self._conninfo = libpq_url(database_url)
        self.sender = secrets.randbelow(2**62)  # tells this process's own notices apart
        self._send_lock = threading.Lock()
        self._sender_conn: psycopg.Connection | None = None
        self._closing = threading.Event()
        self._listening = threading.Event()
        self._listener = threading.Thread(target=self._listen, name="pg-notify-listener", daemon=True)
        self._listener.start()

    def wait_until_listening(self, timeout: float = 10.0) -> bool:
        """Block until the listener has subscribed (tests, start-up); False on timeout."""
        return self._listening.wait(timeout)

    def publish(self, participant_id: int) -> None:
        """Wake local waiters now and tell the other processes (a failed NOTIFY is logged, never raised)."""
        super().publish(participant_id)
        try:
            with self._send_lock:
                if self._sender_conn is None or self._sender_conn.closed:
                    self._sender_conn = psycopg.connect(self._conninfo, autocommit=True)
                self._sender_conn.execute("SELECT pg_notify(%s, %s)", (CHANNEL, f"{self.sender}:{participant_id}"))
        except psycopg.Error:
            log.warning("could not NOTIFY other processes about participant %s", participant_id, exc_info=True)
            with self._send_lock:
                self._sender_conn = None

    def _deliver(self, payload: str) -> None:
        sender, _, participant = payload.partition(":")
        if not (sender.isdigit() and participant.isdigit()):
            log.warning("ignoring a malformed notice %r on %s", payload[:80], CHANNEL)
            return
        if int(sender) != self.sender:
            super().publish(int(participant))

    def _listen(self) -> None:
        while not self._closing.is_set():
            try:
                with psycopg.connect(self._conninfo, autocommit=True) as conn:
                    conn.execute(f"LISTEN {CHANNEL}")
                    self._listening.set()
                    while not self._closing.is_set():
                        for notice in conn.notifies(timeout=0.5):
                            self._deliver(notice.payload)
            except psycopg.Error:
                self._listening.clear()
                if not self._closing.is_set():
                    log.warning("lost the LISTEN connection; reconnecting", exc_info=True)
                    time.sleep(RECONNECT_SECONDS)

    def close(self) -> None:
        """Stop listening and close both connections."""
        self._closing.set()
        self._listener.join(timeout=5)
        with self._send_lock:
            if self._sender_conn is not None:
                self._sender_conn.close()
                self._sender_conn = None

