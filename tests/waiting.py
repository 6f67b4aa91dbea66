"""Waiting in tests for something to happen, with a limit generous enough for a loaded machine.

Tests never assert how long something took: they wait for the condition that shows it happened, and fail only
when it has not happened within a limit far beyond any normal run (the suite must pass with two CPU hogs
running beside it). Speed targets are measured in benchmarks/ instead."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

WAIT_SECONDS = 60.0  # the default limit: a normal run needs a small fraction of it


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
