"""Slots for long-lived connections (change-event streams, 3D-view websockets): a few per participant, where a
newer one ends the oldest, and a cap for the whole process.

Everything here runs on the server's event loop (one thread), so the counts need no lock."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Coroutine, Hashable
from dataclasses import dataclass, field
from typing import Any


@dataclass(eq=False)
class Slot:
    """One open connection of a participant; `wake` is set when something for it happened (it was superseded,
    or its feed has news)."""

    key: Hashable
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    superseded: bool = False


class StreamSlots:
    """At most `per_key` open connections per participant (the newest wins) and `total` in the process."""

    def __init__(self, per_key: int, total: int) -> None:
        if per_key < 1 or total < 1:
            raise ValueError(f"expected at least one slot per participant and in all, got {per_key} and {total}")
        self.per_key, self.total = per_key, total
        self._open: dict[Hashable, list[Slot]] = {}
        self.count = 0

    def take(self, key: Hashable) -> Slot | None:
        """A slot for a new connection of `key`, ending its oldest beyond per_key; None when the process is full."""
        held = self._open.get(key, [])
        if len(held) < self.per_key and self.count >= self.total:
            return None
        while len(held) >= self.per_key:
            oldest = held.pop(0)
            self.count -= 1
            oldest.superseded = True
            oldest.wake.set()
        slot = Slot(key)
        held.append(slot)
        self._open[key] = held
        self.count += 1
        return slot

    def release(self, slot: Slot) -> None:
        """The connection of this slot has ended (a superseded slot was released already)."""
        held = self._open.get(slot.key)
        if held is None or slot not in held:
            return
        held.remove(slot)
        self.count -= 1
        if not held:
            del self._open[slot.key]

    def held(self, key: Hashable) -> int:
        """How many connections of `key` are open."""
        return len(self._open.get(key, ()))


async def run_held(slots: StreamSlots, key: Hashable, work: Coroutine[Any, Any, Any]) -> bool:
    """Run `work` while it holds one of `key`'s slots; a newer connection of `key` cancels it. False, without
    running it, when every slot of the process is taken."""
    slot = slots.take(key)
    if slot is None:
        work.close()
        return False
    task = asyncio.ensure_future(work)
    try:
        while not task.done() and not slot.superseded:
            woken = asyncio.ensure_future(slot.wake.wait())
            try:
                await asyncio.wait({task, woken}, return_when=asyncio.FIRST_COMPLETED)
            finally:
                woken.cancel()
            slot.wake.clear()
    finally:
        if not task.done():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        slots.release(slot)
    if not task.cancelled():
        task.result()  # the work's own error, if any
    return True
