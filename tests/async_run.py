"""Run an asyncio scenario from a synchronous test, whatever loop the test's thread may have running."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")


def run_scenario(scenario: Callable[[], Awaitable[T]], timeout: float = 300.0) -> T:
    """asyncio.run(scenario()) in a thread of its own (a browser test may leave a loop running in this one).

    The limit is a last resort beyond the scenario's own waits (tests.waiting.WAIT_SECONDS)."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(lambda: asyncio.run(scenario())).result(timeout)  # type: ignore[arg-type]
