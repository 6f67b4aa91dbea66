"""The robot seam: what the study server needs from a robot, and a physics-free implementation.

The participant places objects one at a time during a demonstration (each placement returns the new
labels); the robot carries out a query or test execution and reports its trace when it has finished.
The server records the labels and traces the robot reports, never ones it recomputes itself. Tables
are keyed by a string the server chooses (one per participant and task). The MuJoCo robot
(tableteach.sim) implements the same protocol and is selected by Settings.robot.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

from .core.domain import Domain, get_domain

Labels = frozenset[str]


@dataclass(frozen=True)
class RobotProgress:
    """A robot execution: the intended objects, the labels observed so far, and whether it has finished."""

    events: tuple[str, ...]
    trace: tuple[Labels, ...]
    finished: bool


class Robot(Protocol):
    """What the server asks of a robot (the trace robot below, or the MuJoCo scene)."""

    def reset(self, key: str) -> Labels:
        """Clear the table for a new demonstration; the initial labels."""
        ...

    def place(self, key: str, obj: str) -> Labels:
        """The participant places one object; the labels afterwards. ValueError if it cannot be placed."""
        ...

    def placed(self, key: str) -> tuple[str, ...] | None:
        """Objects placed on this table so far, or None if the robot has no table for the key (e.g. after a restart)."""
        ...

    def execute(self, key: str, events: Sequence[str]) -> None:
        """Start carrying out an execution from a cleared table (returns at once)."""
        ...

    def progress(self, key: str) -> RobotProgress | None:
        """The execution under way or finished on this table, or None if the robot knows of none."""
        ...

    def release(self, key: str) -> None:
        """Forget the table (the participant has moved on)."""
        ...


@dataclass
class _Table:
    placed: list[str] = field(default_factory=list)
    execution: tuple[str, ...] | None = None
    trace: tuple[Labels, ...] = ()
    started: float = 0.0


class TraceRobot:
    """A robot without physics: labels are the placed objects (domain.trace_of); executions may take time."""

    def __init__(self, task: str = "dinner", seconds_per_object: float = 0.0) -> None:
        self.domain: Domain = get_domain(task)
        self.seconds_per_object = seconds_per_object
        self._tables: dict[str, _Table] = {}
        self._lock = threading.Lock()

    def reset(self, key: str) -> Labels:
        """Clear the table; the initial labels."""
        with self._lock:
            self._tables[key] = _Table()
        return self.domain.labels(())

    def place(self, key: str, obj: str) -> Labels:
        """Place one object; ValueError naming the problem if it is unknown or already placed."""
        with self._lock:
            table = self._tables.setdefault(key, _Table())
            history = self.domain.step(tuple(table.placed), obj)
            table.placed = list(history)
            table.execution = None
            return self.domain.labels(history)

    def placed(self, key: str) -> tuple[str, ...] | None:
        """Objects placed so far, or None for an unknown table."""
        with self._lock:
            table = self._tables.get(key)
            return None if table is None else tuple(table.placed)

    def execute(self, key: str, events: Sequence[str]) -> None:
        """Start an execution; its trace is revealed one placement per seconds_per_object."""
        trace = tuple(self.domain.trace_of(tuple(events)))
        with self._lock:
            self._tables[key] = _Table(placed=list(events), execution=tuple(events), trace=trace, started=time.monotonic())

    def progress(self, key: str) -> RobotProgress | None:
        """The execution's labels so far and whether it has finished."""
        with self._lock:
            table = self._tables.get(key)
            if table is None or table.execution is None:
                return None
            elapsed = time.monotonic() - table.started
        if self.seconds_per_object <= 0:
            done = len(table.execution)
        else:
            done = min(len(table.execution), int(elapsed / self.seconds_per_object))
        finished = done == len(table.execution) and elapsed >= self.seconds_per_object * len(table.execution)
        return RobotProgress(table.execution, table.trace[: done + 1], finished)

    def release(self, key: str) -> None:
        """Forget the table."""
        with self._lock:
            self._tables.pop(key, None)


def make_robot(name: str, *, seconds_per_object: float = 0.0) -> Robot:
    """The robot implementation a Settings.robot value names."""
    if name == "trace":
        return TraceRobot("dinner", seconds_per_object)
    raise ValueError(f"unknown robot {name!r}; expected 'trace'")
