"""The robot's next query or test, planned ahead while the participant reads the screen.

Planning a robot turn (the posterior update, then the active query or the PUnS plan) costs tens of
milliseconds. Requests that only show where a session is never plan; once a step that leads to a robot
turn is stored, a plan_ahead job (services.background) makes the plan, and the request that starts the
execution (seconds later) finds it ready, or waits for the one being made instead of making it twice.
Plans are deterministic per state (the turn's generator is seeded from the session), so where a plan is
made never changes what it is.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from functools import lru_cache

from ..core import session as core

ROBOT_TURNS = ("query", "test")


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
    """The recent plans of robot turns; step() returns one, made at most once per state in this process.

    It owns no thread: plans are made ahead by the runtime's plan_ahead jobs (services.background) and, if
    none has yet, by the request that needs one."""

    def __init__(self, plan: Callable[[str], core.Step] = step_of, keep: int = 4096) -> None:
        self._plan = plan
        self._keep = keep
        self._plans: OrderedDict[str, core.Step] = OrderedDict()  # oldest first
        self._making: dict[str, threading.Lock] = {}
        self._lock = threading.Lock()

    def step(self, state_json: str) -> core.Step:
        """The next step of this state with its plan: the one made already, or made now (once, if two ask)."""
        with self._lock:
            known = self._plans.get(state_json)
            if known is not None:
                return known
            making = self._making.setdefault(state_json, threading.Lock())
        with making:
            with self._lock:
                known = self._plans.get(state_json)
            if known is None:
                known = self._plan(state_json)
                with self._lock:
                    self._plans[state_json] = known
                    self._plans.move_to_end(state_json)
                    while len(self._plans) > self._keep:
                        self._plans.popitem(last=False)
            with self._lock:
                self._making.pop(state_json, None)
            return known

    def planned(self, state_json: str) -> bool:
        """Whether this state's plan has been made in this process."""
        with self._lock:
            return state_json in self._plans
