"""The robot's next query or test, planned in the background while the participant reads the screen.

Planning a robot turn (the posterior update, then the active query or the PUnS plan) costs tens of
milliseconds. Requests that only show where a session is never plan; once a step that leads to a robot
turn is stored, the plan is made on a background thread, and the request that starts the execution
(seconds later) finds it ready, or waits for the one being made instead of making it twice. Plans are
deterministic per state (the turn's generator is seeded from the session), so where a plan is made
never changes what it is.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import lru_cache

from ..core import session as core

log = logging.getLogger(__name__)

ROBOT_TURNS = ("query", "test")
PLANNER_THREAD = "tableteach-planner"


@lru_cache(maxsize=4096)
def session_of(state_json: str) -> core.SessionState:
    """The core state stored as this JSON (cached: states are immutable values and parsing is not free)."""
    return core.SessionState.from_json(state_json)


def position_of(state_json: str) -> tuple[core.StepKind, int, int]:
    """Where the stored session is (phase, index within it, phase total), without planning anything."""
    return core.position(session_of(state_json))


def step_of(state_json: str) -> core.Step:
    """The next step with the robot's planned execution, if it is a robot turn."""
    return core.next_step(session_of(state_json))


class Planner:
    """Plans robot turns ahead on one background thread and keeps the recent plans; step() returns one."""

    def __init__(self, plan: Callable[[str], core.Step] = step_of, keep: int = 4096) -> None:
        self._plan = plan
        self._keep = keep
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=PLANNER_THREAD)
        self._plans: OrderedDict[str, Future[core.Step]] = OrderedDict()  # made or being made, oldest first
        self._lock = threading.Lock()
        self._closed = False

    def plan_ahead(self, state_json: str) -> None:
        """Start planning this state's robot turn in the background, unless it has none or is planned.

        Never raises: it runs after an action is committed, and planning ahead only saves time."""
        try:
            self._plan_ahead(state_json)
        except Exception:  # noqa: BLE001 - the request that needs the plan makes it and reports any error
            log.warning("could not start planning ahead", exc_info=True)

    def _plan_ahead(self, state_json: str) -> None:
        if position_of(state_json)[0] not in ROBOT_TURNS:
            return
        with self._lock:
            if self._closed or state_json in self._plans:
                return
            future = self._pool.submit(self._plan, state_json)
            self._remember(state_json, future)
        future.add_done_callback(lambda f: self._forget_if_failed(state_json, f))

    def step(self, state_json: str) -> core.Step:
        """The next step of this state with its plan: the one made ahead (waiting for it), or made now."""
        with self._lock:
            future = self._plans.get(state_json)
        if future is not None:
            try:
                return future.result()
            except Exception:  # noqa: BLE001 - planned again below, where the error reaches the caller
                log.warning("planning ahead failed; planning again in the request", exc_info=True)
        step = self._plan(state_json)
        done: Future[core.Step] = Future()
        done.set_result(step)
        with self._lock:
            self._remember(state_json, done)
        return step

    def then(self, state_json: str, use: Callable[[core.Step], None]) -> None:
        """Once this state's robot turn is planned (ahead), call use(step) on the planner's thread; never raises."""
        def run() -> None:
            try:
                use(self.step(state_json))
            except Exception:  # noqa: BLE001 - work done ahead only saves time; the request redoes it
                log.warning("work after planning ahead failed", exc_info=True)

        with self._lock:
            if self._closed:
                return
            self._pool.submit(run)

    def _remember(self, state_json: str, future: Future[core.Step]) -> None:
        self._plans[state_json] = future
        self._plans.move_to_end(state_json)
        while len(self._plans) > self._keep:
            self._plans.popitem(last=False)

    def _forget_if_failed(self, state_json: str, future: Future[core.Step]) -> None:
        if future.cancelled() or future.exception() is not None:
            with self._lock:
                if self._plans.get(state_json) is future:
                    del self._plans[state_json]

    def shutdown(self) -> None:
        """Stop planning ahead (plans not started yet are dropped: requests make them when needed)."""
        with self._lock:
            self._closed = True
        self._pool.shutdown(wait=False, cancel_futures=True)
