"""Change notices: the in-process notifier, and PostgreSQL LISTEN/NOTIFY between two notifiers that stand for
two app processes (each has its own connections, as separate processes would)."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator

import pytest

from tableteach.db import throwaway_postgres
from tableteach.services.notify import LocalNotifier
from tests.async_run import run_scenario
from tests.waiting import WAIT_SECONDS, wait_until




def test_a_waiter_wakes_when_another_thread_publishes_and_times_out_otherwise() -> None:
    notifier = LocalNotifier()

    async def scenario() -> tuple[int, int, int]:
        threading.Timer(0.2, notifier.publish, args=(7,)).start()
        # Its own time-out is far off: only the publish can end this wait (within a generous limit).
        woke = await asyncio.wait_for(notifier.wait(7, 0, timeout=3600), WAIT_SECONDS)
        quiet = await notifier.wait(8, 0, timeout=0.1)  # nobody publishes for participant 8
        # already changed since 0: returns at once, not at its time-out
        behind = await asyncio.wait_for(notifier.wait(7, 0, timeout=3600), WAIT_SECONDS)
        return woke, quiet, behind

    woke, quiet, behind = run_scenario(scenario)
    assert woke == 1  # the counter after the publish: it did not return before it
    assert quiet == 0 and behind == 1


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    if not throwaway_postgres.available():
        pytest.skip("Debian's postgresql package or psycopg is not installed")
    with throwaway_postgres.throwaway_postgres() as url:
        yield url


@pytest.mark.slow
def test_a_notice_published_in_one_process_wakes_a_page_waiting_in_another(postgres_url: str) -> None:
    import psycopg

    from tableteach.db.pg_notify import CHANNEL, PgNotifier, libpq_url

    first, second = PgNotifier(postgres_url), PgNotifier(postgres_url)
    try:
        assert first.wait_until_listening(WAIT_SECONDS) and second.wait_until_listening(WAIT_SECONDS)

        async def scenario() -> int:
            threading.Timer(0.2, first.publish, args=(42,)).start()
            # Only the notice through PostgreSQL can end this wait (its own time-out is far off).
            return await asyncio.wait_for(second.wait(42, 0, timeout=3600), WAIT_SECONDS)

        assert run_scenario(scenario) == 1
        with psycopg.connect(libpq_url(postgres_url), autocommit=True) as conn:
            conn.execute("SELECT pg_notify(%s, %s)", (CHANNEL, "not:a-number"))
            conn.execute("SELECT pg_notify(%s, %s)", (CHANNEL, "1:43"))
        wait_until(lambda: second.count(43) and first.count(43), "both processes to hear the notice for 43")
        assert second.count(43) == 1 and first.count(43) == 1  # the malformed notice changed nothing
        # Notices arrive in commit order, so by now the first process has heard its own notice for 42 come back
        # too: it must not have counted it twice.
        assert first.count(42) == 1 and second.count(42) == 1
    finally:
        first.close()
        second.close()


def test_the_notifier_only_listens_on_postgresql() -> None:
    from tableteach.db.pg_notify import libpq_url
    from tableteach.services.notify import make_notifier

    assert type(make_notifier("sqlite:///x.db")) is LocalNotifier
    assert libpq_url("postgresql+psycopg://u:p@h:5/db") == "postgresql://u:p@h:5/db"
    with pytest.raises(ValueError, match="not PostgreSQL"):
        libpq_url("sqlite:///x.db")


def test_the_app_on_sqlite_needs_no_postgresql_driver(tmp_path) -> None:
    """The base install has no psycopg (it is the `postgres` extra): serving on SQLite must not import it."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['psycopg'] = None\n"  # any `import psycopg` now fails
            "from tableteach.config import Settings\n"
            "from tableteach.web.app import create_app\n"
            f"app = create_app(Settings(database_url='sqlite:///{tmp_path}/t.db', dev_mode=True, "
            f"data_dir='{tmp_path}/data'))\n"
            "print(type(app.state.context.notifier).__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("LocalNotifier")
