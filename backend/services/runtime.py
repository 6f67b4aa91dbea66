"""The study server's runtime: the one owner of every thread of an app process (docs/concurrency.md).

- Job runners (JOB_THREADS threads, or one more than the robot's workers; all but the first `slow_runners`
  take only QUICK_KINDS) carry out durable background work (services.background): a job is a row written in
  the same transaction as the participant's action, claimed here with a lease, done by a handler that is safe
  to run twice, deleted when done, retried with capped exponential backoff when it fails (a busy database, a
  robot that failed), and found again after any restart (a lease that ran out is free; on SQLite, the only
  process there, a starting process frees its predecessor's claims).
- The scheduler (one thread) runs short timed calls: change notices at an execution's stored action
  ends, and the periodic time-out sweep.
- The action queue (ACTION_THREADS threads) runs participant actions that arrive on a library's callback
  thread (a click in the 3D view), so no database write ever happens on viser's threads.
- The learner (LEARNER_THREADS thread) plans robot turns that take seconds to minutes (the exact learner past
  five objects), so that no job runner waits for them (services.background.plan_ahead).
- The robot's own thread and worker processes are started and stopped from here (Robot.start/shutdown).

Handlers never run under another transaction's write lock: an action's jobs are only claimed after it
has committed.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import os
import random
import secrets
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from datetime import timedelta
from typing import TYPE_CHECKING

from sqlalchemy.orm import Session

from ..db import jobs as job_rows
from ..db.tables import utcnow
from ..errors import TryLater

if TYPE_CHECKING:
    from .context import Context

log = logging.getLogger(__name__)

JOB_THREADS = 2
ACTION_THREADS = 2
LEARNER_THREADS = 1  # slow plans queue here, one at a time: on a shared 2-core host more would only contend
CLAIM_BATCH = 4
LEASE_SECONDS = 30.0  # a handler takes well under a second; a claim older than this belongs to a dead process
POLL_SECONDS = 1.0  # other processes' jobs and jobs due later are found at least this often
BACKOFF_FIRST_SECONDS = 0.2
BACKOFF_MAX_SECONDS = 10.0

Handler = Callable[["Context", job_rows.ClaimedJob], None]

# The kinds of background job (services.background has their handlers).
SETTLE, WORK_OUT, FINISH_EXECUTION, PLAN_AHEAD = "settle", "work_out", "finish_execution", "plan_ahead"
# Jobs a participant is waiting on that take milliseconds (a placement's labels, an execution's end). The others
# may wait seconds for a robot worker: the first `slow_runners` runners (one per robot worker) take every kind,
# these first, and the other runners only these, so a placement never waits behind executions being worked out.
QUICK_KINDS = frozenset({SETTLE, FINISH_EXECUTION})
# Jobs that need the state of the process whose request stored them (a placement: the robot's table that the
# participant's live view shows, on that process under sticky routing) are held for that process HELD_SECONDS;
# then any process takes them (the first one died). Another process would place the object where nobody watches,
# and the view would show it only with the next placement.
HELD_KINDS = frozenset({SETTLE})
HELD_SECONDS = 2.0


def backoff(attempts: int) -> float:
    """Seconds before the next try of a job that has failed `attempts` times (capped, with jitter)."""
    base = min(BACKOFF_MAX_SECONDS, BACKOFF_FIRST_SECONDS * 2 ** max(0, attempts - 1))
    return base * (0.75 + 0.5 * random.random())


class Scheduler:
    """One thread running short calls at given monotonic times (notices, sweeps); never the database's writes."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Callable[[], None]]] = []
        self._order = itertools.count()
        self._cv = threading.Condition()
        self._thread: threading.Thread | None = None
        self._stopped = False

    def start(self) -> None:
        """Start the scheduler's thread."""
        with self._cv:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="runtime-scheduler", daemon=True)
                self._thread.start()

    def call_later(self, seconds: float, call: Callable[[], None]) -> None:
        """Run call on the scheduler's thread after `seconds` (it must be quick and never raise for long)."""
        with self._cv:
            heapq.heappush(self._heap, (time.monotonic() + max(0.0, seconds), next(self._order), call))
            self._cv.notify()

    def stop(self) -> None:
        """Drop the calls not yet due and end the thread."""
        with self._cv:
            self._stopped = True
            self._heap.clear()
            self._cv.notify()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._stopped and (not self._heap or self._heap[0][0] > time.monotonic()):
                    self._cv.wait(None if not self._heap else self._heap[0][0] - time.monotonic())
                if self._stopped:
                    return
                _, _, call = heapq.heappop(self._heap)
            try:
                call()
            except Exception:  # noqa: BLE001 - one failed notice must not stop the others
                log.exception("a scheduled call failed")


class Runtime:
    """Starts, feeds and stops the app process's threads: job runners, the scheduler and the action queue."""

    def __init__(self, handlers: dict[str, Handler], *, job_threads: int = JOB_THREADS, slow_runners: int = 1,
                 poll_seconds: float = POLL_SECONDS, lease_seconds: float = LEASE_SECONDS,
                 sweep_seconds: float = 15.0) -> None:
        if slow_runners < 1:
            raise ValueError(f"slow_runners {slow_runners} is below 1: expected at least one runner of every kind")
        self.handlers = handlers
        self.slow_runners = slow_runners  # runners that take every kind; the others take only QUICK_KINDS
        self.job_threads = max(job_threads, slow_runners + 1)
        self.poll_seconds = poll_seconds
        self.lease_seconds = lease_seconds
        self.sweep_seconds = sweep_seconds
        self.owner = f"{os.getpid()}-{secrets.token_hex(4)}"
        self.scheduler = Scheduler()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._actions: ThreadPoolExecutor | None = None
        self._learner: ThreadPoolExecutor | None = None
        self._tables: dict[tuple[int, int | None], threading.Lock] = {}
        self._tables_lock = threading.Lock()
        self._ctx: Context | None = None
        self._started = False
        self.done_count = 0  # jobs finished by this process (tests and benchmarks read it)
        self.failed_count = 0  # handler failures (each retried)

    @property
    def running(self) -> bool:
        """Whether start() has run and stop() has not."""
        return self._started and not self._stop.is_set()

    def start(self, ctx: Context) -> None:
        """Start every thread for this context (once); on SQLite, free the claims a dead predecessor left."""
        if self._started:
            return
        self._started, self._ctx = True, ctx
        if ctx.db.engine.dialect.name == "sqlite":
            try:
                with ctx.db.write() as s:
                    freed = job_rows.release_claims(s)
                    s.commit()
                if freed:
                    log.info("freed %s job claims left by the previous server process", freed)
            except Exception:  # noqa: BLE001 - a busy or not yet migrated database: the leases run out instead
                log.warning("could not free old job claims now; their leases run out instead", exc_info=True)
        ctx.robot.start()
        self.scheduler.start()
        self._actions = ThreadPoolExecutor(max_workers=ACTION_THREADS, thread_name_prefix="runtime-action")
        self._learner = ThreadPoolExecutor(max_workers=LEARNER_THREADS, thread_name_prefix="runtime-learner")
        for i in range(self.job_threads):
            kinds = None if i < self.slow_runners else QUICK_KINDS
            thread = threading.Thread(target=self._run_jobs, args=(kinds,), name=f"runtime-jobs-{i}", daemon=True)
            thread.start()
            self._threads.append(thread)
        if self.sweep_seconds > 0:
            self.scheduler.call_later(0.0, self._sweep)

    def wake(self) -> None:
        """New jobs were committed: look for them now rather than at the next poll."""
        self._wake.set()

    def call_later(self, seconds: float, call: Callable[[], None]) -> None:
        """A short call on the scheduler's thread after `seconds`."""
        self.scheduler.call_later(seconds, call)

    def submit(self, action: Callable[[], object]) -> Future[object]:
        """Run a participant action that arrived on a library's thread (a click) on the action queue."""
        if self._actions is None:
            raise RuntimeError("the runtime has not started: expected Runtime.start(ctx) at app start-up")
        return self._actions.submit(action)

    def think(self, call: Callable[[], object]) -> Future[object] | None:
        """Run a slow learner call (a plan past five objects) on the learner's thread; None when the runtime has not
        started or is stopping (the caller then leaves it to whoever needs the plan, who makes it then)."""
        if self._learner is None or self._stop.is_set():
            return None
        try:
            return self._learner.submit(call)
        except RuntimeError:
            return None  # shutting down

    def stop(self) -> None:
        """Stop taking work, let handlers under way end, stop the robot; unfinished jobs stay in the database."""
        if not self._started or self._stop.is_set():
            return
        self._stop.set()
        self._wake.set()
        for thread in self._threads:
            thread.join(timeout=30)
        self.scheduler.stop()
        if self._actions is not None:
            self._actions.shutdown(wait=True, cancel_futures=True)
        if self._learner is not None:  # a plan under way is not waited for: whoever needs it makes it again
            self._learner.shutdown(wait=False, cancel_futures=True)
        if self._ctx is not None:
            self._ctx.robot.shutdown()

    def run_due_jobs(self) -> int:
        """Claim and carry out the jobs due now, here (tools and tests; the runners do this all the time)."""
        return self._run_batch()

    # -- job runners ---------------------------------------------------------------------------------
    def _run_jobs(self, kinds: frozenset[str] | None) -> None:
        while not self._stop.is_set():
            # A read first: claiming takes the write lock, which an idle runner should not take every second.
            wait = self._until_claimable(kinds)
            if wait > 0:
                self._wake.wait(wait)
                self._wake.clear()
                continue
            try:
                ran = self._run_batch(kinds)
            except TryLater:
                ran = 0
                self._stop.wait(backoff(2))  # the database is busy or gone: try again shortly
            except Exception:  # noqa: BLE001 - a runner never dies; the job stays and is tried again
                log.exception("a job runner failed; it goes on")
                ran = 0
                self._stop.wait(backoff(3))
            if ran == 0:  # another runner took them first
                self._wake.wait(0.05)
                self._wake.clear()

    def _until_claimable(self, kinds: frozenset[str] | None = None) -> float:
        """Seconds until a stored job (of these kinds; None: any) can be claimed (0: now), at most the poll interval
        (other processes' jobs)."""
        ctx = self._ctx
        if ctx is None:
            return self.poll_seconds
        try:
            with ctx.db.read() as s:
                at = job_rows.next_claimable(s, owner=self.owner, kinds=kinds)
        except Exception:  # noqa: BLE001 - polling again later finds it
            return self.poll_seconds
        if at is None:
            return self.poll_seconds
        from .context import aware

        left = ((aware(at) or utcnow()) - utcnow()).total_seconds()
        return 0.0 if left <= 0 else min(self.poll_seconds, left)

    def _run_batch(self, kinds: frozenset[str] | None = None) -> int:
        ctx = self._ctx
        assert ctx is not None, "the runtime has not started"
        with ctx.db.write() as s:
            claimed = job_rows.claim_jobs(s, owner=self.owner, lease_seconds=self.lease_seconds, limit=CLAIM_BATCH,
                                          kinds=kinds, first=QUICK_KINDS)
            s.commit()
        for job in claimed:
            self._run_one(ctx, job)
        return len(claimed)

    def _run_one(self, ctx: Context, job: job_rows.ClaimedJob) -> None:
        handler = self.handlers.get(job.kind)
        try:
            if handler is None:
                raise ValueError(f"no handler for job kind {job.kind!r}: expected one of {sorted(self.handlers)}")
            with self.table_lock(job.participant_id, job.task_index):
                handler(ctx, job)
        except Exception as exc:  # noqa: BLE001 - every failure is retried; the job stays until it succeeds
            self.failed_count += 1
            wait = backoff(job.attempts)
            log.warning("job %s (%s, participant %s) failed on try %s; again in %.1f s: %s", job.id, job.kind,
                        job.participant_id, job.attempts, wait, exc)
            error, due = f"{type(exc).__name__}: {exc}", utcnow() + timedelta(seconds=wait)
            self._settle(ctx, lambda s: job_rows.retry_job(s, job_id=job.id, due_at=due, error=error))
            return
        self.done_count += 1
        self._settle(ctx, lambda s: job_rows.finish_job(s, job_id=job.id))

    def _settle(self, ctx: Context, write: Callable[[Session], None]) -> None:
        """Record a job's end, trying again with backoff while its lease lasts (a busy database); if it never
        succeeds, the lease runs out and the job runs again (handlers are idempotent)."""
        deadline = time.monotonic() + self.lease_seconds
        attempt = 0
        while True:
            attempt += 1
            try:
                with ctx.db.write() as s:
                    write(s)
                    s.commit()
                return
            except Exception:  # noqa: BLE001 - see docstring
                wait = backoff(attempt)
                if time.monotonic() + wait >= deadline or self._stop.is_set():
                    log.warning("could not record the end of a job; it runs again after its lease", exc_info=True)
                    return
                self._stop.wait(wait)

    def table_lock(self, participant_id: int, task_index: int | None) -> threading.Lock:
        """One lock per participant table: this process runs one job (or view rebuild) of a table at a time."""
        key = (participant_id, task_index)
        with self._tables_lock:
            lock = self._tables.get(key)
            if lock is None:
                lock = self._tables[key] = threading.Lock()
            return lock

    # -- periodic ------------------------------------------------------------------------------------
    def _sweep(self) -> None:
        """Every sweep_seconds: screen out participants idle past their study's time-out, and remove this host's
        cached recordings of participants erased elsewhere (on the action queue)."""
        if self._stop.is_set() or self._ctx is None or self._actions is None:
            return
        from .timeouts import forget_erased_copies, sweep_timeouts

        ctx = self._ctx
        try:
            self._actions.submit(lambda: sweep_timeouts(ctx))
            self._actions.submit(lambda: forget_erased_copies(ctx))
        except RuntimeError:
            return  # shutting down
        self.scheduler.call_later(self.sweep_seconds, self._sweep)
