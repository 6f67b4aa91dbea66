"""Waiting in tests for something to happen, with a limit generous enough for a loaded machine.

Tests never assert how long something took: they wait for the condition that shows it happened, and fail only
when it has not happened within a limit far beyond any normal run (the suite must pass with two CPU hogs
running beside it). Speed targets are measured in benchmarks/ instead."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

# The default limit: a normal run needs a small fraction of it, and a longer one costs nothing while tests pass
# (a wait ends as soon as its condition holds). Imports alone took 41 s instead of 3 on this 2-core machine at
# load 23.
WAIT_SECONDS = 120.0


def wait_until(condition: Callable[[], T], what: str, timeout: float = WAIT_SECONDS, interval: float = 0.05) -> T:
    """The first truthy value of condition(), asked every `interval` seconds; fails naming `what` after `timeout`."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout:.0f} s for {what}, and it did not happen (last seen: {value!r})")
        time.sleep(interval)
