"""Wake a participant's open page when their state changes: a counter per participant that threads bump and
asyncio handlers wait on. In one process; tableteach.db.pg_notify carries it across processes."""

from __future__ import annotations

import asyncio
import threading


class LocalNotifier:
    """Per-participant change counters; publish() from any thread, wait() from the event loop."""

    def __init__(self) -> None:
        self._counts: dict[int, int] = {}
        self._waiters: dict[int, set[tuple[asyncio.AbstractEventLoop, asyncio.Event]]] = {}
        self._lock = threading.Lock()

    def publish(self, participant_id: int) -> None:
        """The participant's state changed: wake everyone waiting for them (thread-safe)."""
        with self._lock:
            self._counts[participant_id] = self._counts.get(participant_id, 0) + 1
            waiters = list(self._waiters.get(participant_id, ()))
        for loop, event in waiters:
            try:
                loop.call_soon_threadsafe(event.set)
            except RuntimeError:
                pass  # that loop has closed; its waiter is gone

    def count(self, participant_id: int) -> int:
        """How many changes were published for the participant so far."""
        with self._lock:
            return self._counts.get(participant_id, 0)

    async def wait(self, participant_id: int, seen: int, timeout: float) -> int:
        """Return the participant's change count once it differs from `seen`, or after `timeout` seconds."""
        waiter = (asyncio.get_running_loop(), asyncio.Event())
        with self._lock:
            if self._counts.get(participant_id, 0) != seen:
                return self._counts.get(participant_id, 0)
            self._waiters.setdefault(participant_id, set()).add(waiter)
        try:
            await asyncio.wait_for(waiter[1].wait(), timeout)
        except asyncio.TimeoutError:
            pass
        finally:
            with self._lock:
                waiting = self._waiters.get(participant_id)
                if waiting is not None:
                    waiting.discard(waiter)
                    if not waiting:
                        del self._waiters[participant_id]
        return self.count(participant_id)
