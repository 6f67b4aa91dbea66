"""The robot seam: what the study server needs from a robot, and a physics-free implementation.

The participant places objects one at a time during a demonstration (each placement returns the new
labels); the robot works out a query or test execution whole (plan_execution: its trace and its clock).
The server records the labels and traces the robot reports, never ones it recomputes itself. Tables
are keyed by a string the server chooses (one per participant and task). The MuJoCo robot
(tableteach.sim.robot) implements the same protocol with a 3D view; this seam never imports it: the app is
composed with one robot or the other in tableteach.web.robots, the only place that imports tableteach.sim.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from .core.domain import Domain, get_domain, objects_task
from .scenes.spec import SceneSpec

Labels = frozenset[str]


@dataclass(frozen=True)
class ExecutionPlan:
    """A whole execution worked out before it is shown: the labels after each action and when each action ends.

    `action_ends[i]` is the number of seconds after the start of the motion at which action i has been
    shown; `viewable` is True when a recording of the motion (.viser) was saved for the browser to play.
    Executions are deterministic given the table's key and the events, so any process computes the same plan.
    """

    events: tuple[str, ...]
    trace: tuple[Labels, ...]
    action_ends: tuple[float, ...]
    viewable: bool = False


@dataclass(frozen=True)
class RobotActivity:
    """What a table's robot is doing right now, for the participant page's status line."""

    moving: bool
    caption: str  # e.g. "The robot is placing the bowl (2 of 4)"; empty when idle
    watchers: int  # browsers showing the table's 3D view


@dataclass(frozen=True)
class ViewAddress:
    """Where the app's websocket proxy connects one browser to a table's 3D view: a local port and a path."""

    port: int
    path: str


class Robot(Protocol):
    """Everything the server asks of a robot (the trace robot below, or the MuJoCo scene in tableteach.sim).

    Tables are keyed by a string the server chooses ("<participant id>/<task index>"). Calls may come from
    any thread of the runtime; implementations are thread-safe.
    """

    works_in_background: bool
    """True for a robot that takes time (physics): the server places objects and works executions out in
    background jobs (services.background) instead of inside the request."""

    shows_view: bool
    """True for a robot with a 3D view for the browser (open_view, and recordings it plays)."""

    on_change: Callable[[str], None] | None
    """Told a table's key whenever what the robot shows of it changes (a motion starts or ends)."""

    scene_of: Callable[[str], SceneSpec | None] | None
    """Says which objects a table's key has: a study's own (its scene specification) or the dinner table's (None).
    Asked once per key and process when the robot first meets the table (a study's scene never changes once
    participants have joined), on whichever thread calls the robot; it reads the database and writes nothing."""

    def start(self) -> None:
        """Start the robot's own threads, if any (the runtime calls it once at start-up)."""
        ...

    def shutdown(self) -> None:
        """Stop everything the robot runs (threads, views, worker processes); the runtime calls it at the end."""
        ...

    def reset(self, key: str) -> Labels:
        """Clear the table for a new demonstration; the initial labels."""
        ...

    def place(self, key: str, obj: str) -> Labels:
        """The participant places one object; the labels afterwards. ValueError if it cannot be placed."""
        ...

    def restore(self, key: str, placed: Sequence[str]) -> None:
        """Rebuild the table holding exactly these placements, showing the result but not the motion (a table
        lost to a restart, another process, or freed while idle)."""
        ...

    def placed(self, key: str) -> tuple[str, ...] | None:
        """Objects placed on this table so far, or None if the robot has no table for the key (e.g. after a restart)."""
        ...

    def trace(self, key: str) -> tuple[Labels, ...] | None:
        """The table's labels after its reset and after each placement so far (None as for placed)."""
        ...

    def plan_execution(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> ExecutionPlan:
        """Work the whole execution out now (nothing is shown) and keep its recording as `name` if it records any.

        `speed` (the study's robot_speed) divides the action ends, and a recording for the browser plays at it.
        ValueError names the first object that cannot be placed. The server stores the plan in the database,
        so any app process can say how far the execution has got (tableteach.services.executions).
        """
        ...

    def release(self, key: str) -> None:
        """Forget the table's contents (the participant has moved on to another step)."""
        ...

    def save_recording(self, key: str, name: str) -> None:
        """Keep the table's motion since its last reset as `name`, if it records any.

        `name` has the form participant-<uid>/task-<i>/<kind>-<j> (the participant's random uid).
        """
        ...

    def close(self, key: str) -> None:
        """The participant is done with this table: free it and anything shown of it."""
        ...

    def set_speed(self, key: str, speed: float) -> None:
        """Show this table's motions `speed` times faster (the study's robot_speed)."""
        ...

    def open_view(self, key: str, on_click: Callable[[str], None] | None) -> ViewAddress | None:
        """Where a browser connects to the table's 3D view (None without views); on_click gets clicked objects
        on a library thread and must only queue them."""
        ...

    def click_done(self, key: str) -> None:
        """A click handed to on_click has been carried out or refused: the table takes clicks again."""
        ...

    def has_view(self, key: str) -> bool:
        """Whether a browser shows the table's 3D view now."""
        ...

    def activity(self, key: str) -> RobotActivity | None:
        """What the robot at this table is doing, or None if the robot has no such table."""
        ...

    def view_count(self) -> int:
        """Browsers connected to any table's 3D view in this process."""
        ...


@dataclass
class _Table:
    placed: list[str] = field(default_factory=list)


class TraceRobot:
    """A robot without physics: labels are the placed objects (domain.trace_of); executions take
    seconds_per_object per action on their stored clock."""

    works_in_background = False
    shows_view = False

    def __init__(self, task: str = "dinner", seconds_per_object: float = 0.0) -> None:
        self.on_change: Callable[[str], None] | None = None
        self.scene_of: Callable[[str], SceneSpec | None] | None = None
        self.domain: Domain = get_domain(task)
        self.seconds_per_object = seconds_per_object
        self._tables: dict[str, _Table] = {}
        self._domains: dict[str, Domain] = {}  # keys whose study has its own objects
        self._lock = threading.Lock()

    def domain_of(self, key: str) -> Domain:
        """The objects a table has: its study's own (scene_of), else the robot's task's."""
        with self._lock:
            known = self._domains.get(key)
        if known is not None:
            return known
        spec = None if self.scene_of is None else self.scene_of(key)
        domain = self.domain if spec is None else get_domain(objects_task(spec.names))
        with self._lock:
            self._domains[key] = domain
        return domain

    def reset(self, key: str) -> Labels:
        """Clear the table; the initial labels."""
        domain = self.domain_of(key)
        with self._lock:
            self._tables[key] = _Table()
        return domain.labels(())

    def place(self, key: str, obj: str) -> Labels:
        """Place one object; ValueError naming the problem if it is unknown or already placed."""
        domain = self.domain_of(key)
        with self._lock:
            table = self._tables.setdefault(key, _Table())
            history = domain.step(tuple(table.placed), obj)
            table.placed = list(history)
            return domain.labels(history)

    def restore(self, key: str, placed: Sequence[str]) -> None:
        """The table holding exactly these placements."""
        self.reset(key)
        for obj in placed:
            self.place(key, obj)

    def placed(self, key: str) -> tuple[str, ...] | None:
        """Objects placed so far, or None for an unknown table."""
        with self._lock:
            table = self._tables.get(key)
            return None if table is None else tuple(table.placed)

    def trace(self, key: str) -> tuple[Labels, ...] | None:
        """The labels after the reset and after each placement so far, or None for an unknown table."""
        placed = self.placed(key)
        return None if placed is None else tuple(self.domain_of(key).trace_of(placed))

    def plan_execution(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> ExecutionPlan:
        """The execution's trace, one action per seconds_per_object / speed; ValueError names an object it cannot
        place or a speed that is not positive."""
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.5")
        domain = self.domain_of(key)
        history: tuple[str, ...] = ()
        for obj in events:
            history = domain.step(history, obj)
        events = tuple(events)
        ends = tuple(self.seconds_per_object / speed * (i + 1) for i in range(len(events)))
        return ExecutionPlan(events, tuple(domain.trace_of(events)), ends)

    def release(self, key: str) -> None:
        """Forget the table."""
        with self._lock:
            self._tables.pop(key, None)

    def save_recording(self, key: str, name: str) -> None:
        """Nothing to keep: the trace robot does not move."""

    def close(self, key: str) -> None:
        """Forget the table (and which objects it had)."""
        self.release(key)
        with self._lock:
            self._domains.pop(key, None)

    def start(self) -> None:
        """No threads to start."""

    def shutdown(self) -> None:
        """Forget every table."""
        with self._lock:
            self._tables.clear()

    def set_speed(self, key: str, speed: float) -> None:
        """Nothing is shown, so nothing plays faster."""

    def open_view(self, key: str, on_click: Callable[[str], None] | None) -> ViewAddress | None:
        """No 3D view."""
        return None

    def click_done(self, key: str) -> None:
        """No view, so no clicks."""

    def has_view(self, key: str) -> bool:
        """No 3D view."""
        return False

    def activity(self, key: str) -> RobotActivity | None:
        """Never moving: executions run on their stored clock (services.executions)."""
        return None

    def view_count(self) -> int:
        """No 3D views."""
        return 0
