"""Change notices: the in-process notifier, and PostgreSQL LISTEN/NOTIFY between two notifiers that stand for
two app processes (each has its own connections, as separate processes would)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from tableteach.db import throwaway_postgres
from tableteach.services.notify import LocalNotifier
from tests.async_run import run_scenario




def test_a_waiter_wakes_when_another_thread_publishes_and_times_out_otherwise() -> None:
    notifier = LocalNotifier()

    async def scenario() -> tuple[int, float, int, int]:
        threading.Timer(0.2, notifier.publish, args=(7,)).start()
        started = time.monotonic()
        woke = await notifier.wait(7, 0, timeout=5)
        took = time.monotonic() - started
        quiet = await notifier.wait(8, 0, timeout=0.1)  # nobody publishes for participant 8
        behind = await notifier.wait(7, 0, timeout=5)  # already changed since 0: returns at once
        return woke, took, quiet, behind

    woke, took, quiet, behind = run_scenario(scenario)
    assert woke == 1 and 0.15 < took < 2
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
        assert first.wait_until_listening() and second.wait_until_listening()

        async def scenario() -> tuple[int, float]:
            threading.Timer(0.2, first.publish, args=(42,)).start()
            started = time.monotonic()
            woke = await second.wait(42, 0, timeout=5)
            return woke, time.monotonic() - started

        woke, took = run_scenario(scenario)
        assert woke == 1 and took < 2
        time.sleep(0.3)  # the first process's own notice comes back to it too: it must not count it twice
        assert first.count(42) == 1 and second.count(42) == 1
        with psycopg.connect(libpq_url(postgres_url), autocommit=True) as conn:
            conn.execute("SELECT pg_notify(%s, %s)", (CHANNEL, "not:a-number"))
            conn.execute("SELECT pg_notify(%s, %s)", (CHANNEL, "1:43"))
        deadline = time.monotonic() + 5
        while (second.count(43) == 0 or first.count(43) == 0) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert second.count(43) == 1 and first.count(43) == 1  # the malformed notice changed nothing
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
