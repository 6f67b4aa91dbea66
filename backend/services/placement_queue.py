"""Placements waiting for the robot, per table (services.placements): run on a few threads, waited for by table."""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

PLACEMENT_THREADS = 4  # MuJoCo releases the interpreter lock while it steps: placements overlap on several cores


class PlacementQueue:
    """Placements waiting for the robot, per table: the last one's future; one queue per app context."""

    def __init__(self) -> None:
        self._pool: ThreadPoolExecutor | None = None
        self._last: dict[str, Future[None]] = {}
        self._lock = threading.Lock()

    def submit(self, key: str, job: Callable[[], None]) -> Future[None]:
        """Run job on a placement thread; its future. The caller keeps one table's jobs in order by waiting
        for the earlier ones first (services.placements.sync_table)."""
        with self._lock:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(max_workers=PLACEMENT_THREADS, thread_name_prefix="placement")
            future = self._pool.submit(job)
            self._last[key] = future
        future.add_done_callback(lambda done: self._forget(key, done))
        return future

    def wait(self, key: str, timeout: float) -> None:
        """Until the table's placements submitted so far have ended (TimeoutError past timeout seconds)."""
        with self._lock:
            last = self._last.get(key)
        if last is not None:
            _wait_quietly(last, timeout)

    def shutdown(self) -> None:
        """Finish the placements under way (each is a fraction of a second) and stop the threads."""
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)

    def _forget(self, key: str, done: Future[None]) -> None:
        with self._lock:
            if self._last.get(key) is done:
                del self._last[key]


def _wait_quietly(future: Future[None], timeout: float | None = None) -> None:
    """Wait for a placement job; its own failure was logged where it happened."""
    try:
        future.result(timeout)
    except TimeoutError:
        raise
    except Exception:  # noqa: BLE001 - logged by the job; the table is rebuilt from the stored placements
        pass
