"""Task domains (environment MDPs): the dinner table and the synthetic waypoint/threat domain.

An environment state is the history of successful moves. Dinner table: placing an object is
permanent and each object is placed at most once; the state's labels are the placed objects.
Synthetic: the robot moves to one of the waypoints or threats, succeeding with probability 0.8
(else it stays); the state's label is its current location. Both have a stop action (``None``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from .clauses import ClauseSpace

STOP = None
DINNER_OBJECTS = ("dinner_plate", "small_plate", "bowl", "knife", "fork")
# The paper's two user-study tasks as ground-truth formulas over the dinner objects.
DINNER_TASK_FORMULAS = {
    "task1": "F(dinner_plate) & F(small_plate) & F(bowl) & F(knife) & F(fork) & (!small_plate U dinner_plate)"
    " & (!bowl U small_plate) & (!bowl U dinner_plate)",
    "task2": "G(!small_plate) & F(dinner_plate) & F(bowl) & (!bowl U dinner_plate)",
}

History = tuple[str, ...]


@dataclass(frozen=True)
class Domain:
    """A task's propositions, which clauses they admit, and its action dynamics."""

    name: str
    propositions: tuple[str, ...]
    orderable: tuple[str, ...]
    forbiddable: tuple[str, ...]
    persistent: bool
    success_prob: float
    verb: str

    @cached_property
    def clause_space(self) -> ClauseSpace:
        """The template clause universe of this domain."""
        return ClauseSpace(self.orderable, self.forbiddable, verb=self.verb)

    def labels(self, history: History) -> frozenset[str]:
        """Propositions true in the state reached by a history of successful moves."""
        if self.persistent:
            return frozenset(history)
        return frozenset(history[-1:])

    def actions(self, history: History) -> list[str | None]:
        """Available actions: a proposition to make true, or STOP (None)."""
        if self.persistent:
            return [p for p in self.propositions if p not in history] + [STOP]
        return list(self.propositions) + [STOP]

    def step(self, history: History, action: str, rng: np.random.Generator | None = None) -> History:
        """Apply a move; with success probability below 1 an rng decides whether it happens."""
        if action not in self.propositions:
            raise ValueError(f"unknown action {action!r}; expected one of {', '.join(self.propositions)}")
        if self.persistent and action in history:
            raise ValueError(f"{action!r} is already placed; a placed object cannot be placed again")
        if self.success_prob < 1.0:
            if rng is None:
                raise ValueError(f"domain {self.name!r} is stochastic: step() needs an rng")
            if rng.random() >= self.success_prob:
                return history
        return history + (action,)

    def trace_of(self, events: tuple[str, ...] | list[str]) -> list[frozenset[str]]:
        """The trace of a sequence of successful moves, starting with the initial state."""
        trace = [self.labels(())]
        for i in range(len(events)):
            trace.append(self.labels(tuple(events[: i + 1])))
        return trace

    def check_trace(self, trace: list[frozenset[str]] | list[list[str]]) -> None:
        """Raise ValueError naming the problem if a trace is empty or names unknown propositions."""
        if len(trace) == 0:
            raise ValueError("a trace must have at least one state (the initial state)")
        known = set(self.propositions)
        for t, state in enumerate(trace):
            unknown = set(state) - known
            if unknown:
                raise ValueError(
                    f"state {t} names unknown proposition(s) {', '.join(sorted(unknown))}; "
                    f"expected some of {', '.join(self.propositions)}"
                )


def dinner_domain() -> Domain:
    """The dinner table: five objects, each may be required, ordered or forbidden."""
    return Domain("dinner", DINNER_OBJECTS, DINNER_OBJECTS, DINNER_OBJECTS, True, 1.0, "place")


def synthetic_domain(n_waypoints: int = 5, n_threats: int = 5, success_prob: float = 0.8) -> Domain:
    """The paper's synthetic domain: waypoints to visit in some order and threats to avoid."""
    waypoints = tuple(f"w{i}" for i in range(n_waypoints))
    threats = tuple(f"t{i}" for i in range(n_threats))
    return Domain("synthetic", waypoints + threats, waypoints, threats, False, success_prob, "visit")


DOMAINS = {"dinner": dinner_domain, "synthetic": synthetic_domain}
OBJECTS_PREFIX = "objects:"  # a task with its own objects: "objects:lunch_box,apple,napkin"


def objects_task(names: tuple[str, ...] | list[str]) -> str:
    """The task name of placing these objects (a dinner-like task over a study's own objects)."""
    return OBJECTS_PREFIX + ",".join(names)


def objects_domain(names: tuple[str, ...]) -> Domain:
    """The task of placing these objects, each at most once, in any order (the dinner table's dynamics)."""
    return Domain("objects", names, names, names, True, 1.0, "place")


@lru_cache(maxsize=64)
def get_domain(name: str) -> Domain:
    """A domain by name ('dinner', 'synthetic', or 'objects:a,b,...' for a task with its own objects)."""
    if name.startswith(OBJECTS_PREFIX):
        names = tuple(name[len(OBJECTS_PREFIX):].split(","))
        if len(names) < 2 or len(set(names)) != len(names) or not all(names):
            raise ValueError(f"task {name!r} names its objects badly; expected 'objects:' and 2 or more distinct "
                             "comma-separated names")
        return objects_domain(names)
    if name not in DOMAINS:
        raise ValueError(f"unknown task {name!r}; expected one of {', '.join(DOMAINS)} or objects:a,b,...")
    return DOMAINS[name]()
