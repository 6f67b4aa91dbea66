"""Change notices per participant inside one process: a counter bumped after every change of their state or
robot, awaited by the page's event stream. Standard library only, so that the database adapter's
cross-process notifier (tableteach.db.pg_notify) can build on it without importing the services."""

from __future__ import annotations

import asyncio
import threading


class LocalNotifier:
    """In-process notices: publish() from any thread, wait() from any event loop."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counters: dict[int, int] = {}
        self._waiters: dict[int, set[tuple[asyncio.AbstractEventLoop, asyncio.Event]]] = {}

    def counter(self, participant_id: int) -> int:
        """How many changes of this participant were published so far (0 if none)."""
        with self._lock:
            return self._counters.get(participant_id, 0)

    count = counter  # the name the cross-process notifier's tests use

    def publish(self, participant_id: int) -> None:
        """The participant's state or robot changed: wake everyone waiting for them (thread-safe)."""
        with self._lock:
            self._counters[participant_id] = self._counters.get(participant_id, 0) + 1
            waiters = list(self._waiters.get(participant_id, ()))
        for loop, event in waiters:
            try:
                loop.call_soon_threadsafe(event.set)
            except RuntimeError:
                pass  # that loop has closed: its waiter is gone

    async def wait(self, participant_id: int, seen: int, timeout: float) -> int:
        """The participant's change counter as soon as it differs from `seen`, or after `timeout` seconds."""
        event = asyncio.Event()
        entry = (asyncio.get_running_loop(), event)
        with self._lock:
            current = self._counters.get(participant_id, 0)
            if current != seen:
                return current
            self._waiters.setdefault(participant_id, set()).add(entry)
        try:
            await asyncio.wait_for(event.wait(), timeout)
        except asyncio.TimeoutError:
            pass
        finally:
            with self._lock:
                waiting = self._waiters.get(participant_id)
                if waiting is not None:
                    waiting.discard(entry)
                    if not waiting:
                        del self._waiters[participant_id]
        return self.counter(participant_id)

    def close(self) -> None:
        """Nothing to release in one process (PgNotifier closes its connections)."""
