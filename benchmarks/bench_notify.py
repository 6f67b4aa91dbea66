"""Change-notice latency: how soon a waiting page's event stream hears that a participant's state changed.

    .venv/bin/python benchmarks/bench_notify.py [--samples 200] [--no-postgres]

- in the process: a waiter (as an open page's event stream) awaits LocalNotifier.wait while another thread
  publishes, as an action's commit does; time from the publish call to the waiter running again.
- between processes (PostgreSQL LISTEN/NOTIFY): two PgNotifiers, each with its own connections as two app
  processes have, on a throwaway PostgreSQL cluster; one publishes, a waiter on the other wakes. This is the
  path by which a page on process b follows an execution started on process a (tests/web/test_processes.py
  checks that it does, this measures how soon). Skipped without Debian's postgresql package.

Each sample is a fresh publish and a real wake-up (nothing cached). Prints the median, p95 and the largest
latency in milliseconds; asserts nothing (the tests check behaviour, not speed).
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import threading
import time

from tableteach.services.notify import LocalNotifier

PARTICIPANT = 7
PUBLISH_AFTER = 0.005  # seconds: the waiter is parked before the publish comes
WAIT_LIMIT = 60.0


def _publish(publisher: LocalNotifier, sent: list[float]) -> None:
    """Note the time, then publish (on a timer thread, as an action's commit does on a request thread)."""
    sent.append(time.perf_counter())
    publisher.publish(PARTICIPANT)


def wake_latencies(publisher: LocalNotifier, waiter: LocalNotifier, samples: int, label: str) -> list[float]:
    """Seconds from publisher.publish() to a parked waiter.wait() returning, once per sample."""

    async def measure() -> list[float]:
        out: list[float] = []
        for i in range(samples):
            seen = waiter.counter(PARTICIPANT)
            sent: list[float] = []
            threading.Timer(PUBLISH_AFTER, _publish, args=(publisher, sent)).start()
            woke = await waiter.wait(PARTICIPANT, seen, timeout=WAIT_LIMIT)
            arrived = time.perf_counter()
            if woke == seen or not sent:
                raise RuntimeError(f"{label}: sample {i + 1} got no notice within {WAIT_LIMIT:.0f} s")
            out.append(arrived - sent[0])
            if (i + 1) % max(1, samples // 4) == 0:
                print(f"  {label}: {i + 1}/{samples} samples", flush=True)
        return out

    return asyncio.run(measure())


def report(label: str, seconds: list[float]) -> None:
    """One line: median, p95 and maximum in milliseconds."""
    ms = sorted(1000 * s for s in seconds)
    p95 = ms[min(len(ms) - 1, round(0.95 * (len(ms) - 1)))]
    print(f"{label}: median {statistics.median(ms):.2f} ms, p95 {p95:.2f} ms, max {ms[-1]:.2f} ms "
          f"({len(ms)} samples)")


def main() -> None:
    """Measure both paths and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=200, help="publishes per path (default 200)")
    parser.add_argument("--no-postgres", action="store_true", help="only the in-process notifier")
    args = parser.parse_args()
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")

    local = LocalNotifier()
    report("in the process (LocalNotifier)", wake_latencies(local, local, args.samples, "in the process"))

    if args.no_postgres:
        return
    from tableteach.db import throwaway_postgres

    if not throwaway_postgres.available():
        print("between processes: skipped (Debian's postgresql package or psycopg is not installed)")
        return
    from tableteach.db.pg_notify import PgNotifier

    with throwaway_postgres.throwaway_postgres() as url:
        first, second = PgNotifier(url), PgNotifier(url)
        try:
            if not (first.wait_until_listening(WAIT_LIMIT) and second.wait_until_listening(WAIT_LIMIT)):
                raise RuntimeError(f"the notifiers did not start listening within {WAIT_LIMIT:.0f} s")
            latencies = wake_latencies(first, second, args.samples, "between processes")
        finally:
            first.close()
            second.close()
    report("between processes (PostgreSQL LISTEN/NOTIFY)", latencies)


if __name__ == "__main__":
    main()
