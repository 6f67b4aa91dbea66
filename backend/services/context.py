"""The request context shared by every service (settings, database, robot, tab leases) and small helpers."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from functools import lru_cache
from typing import Any

from ..config import Settings
from ..db import repository as repo
from ..db.engine import Database
from ..errors import Conflict
from ..robot import Robot, TraceRobot
from .notify import LocalNotifier, make_notifier, participant_of_key
from .placement_queue import PlacementQueue
from .planning import Planner


@lru_cache(maxsize=1)
def app_version() -> str:
    """The installed tableteach version, written into every event."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tableteach")
    except PackageNotFoundError:
        return "unknown"


TAB_LEASE_SECONDS = 15.0


class TabLeases:
    """Which browser tab holds each participant's page; in the process, like the robot's executions."""

    def __init__(self, seconds: float = TAB_LEASE_SECONDS) -> None:
        self.seconds = seconds
        self._holders: dict[int, tuple[str, float]] = {}
        self._lock = threading.Lock()

    def claim(self, participant_id: int, tab_id: str, *, takeover: bool = False) -> bool:
        """Hold or renew the lease; False while another tab's lease is still fresh (unless takeover)."""
        now = time.monotonic()
        with self._lock:
            holder = self._holders.get(participant_id)
            if holder is not None and holder[0] != tab_id and holder[1] > now and not takeover:
                return False
            self._holders[participant_id] = (tab_id, now + self.seconds)
            return True

    def release(self, participant_id: int, tab_id: str) -> None:
        """Give the lease up (the tab is closing or reloading) if this tab holds it."""
        with self._lock:
            if self._holders.get(participant_id, ("",))[0] == tab_id:
                del self._holders[participant_id]


@dataclass
class Context:
    """What every action needs: the database, the robot and the settings (plus tab leases, the planner, the page
    notifier and the placements waiting for the robot)."""

    db: Database
    robot: Robot
    settings: Settings
    tabs: TabLeases = field(default_factory=TabLeases)
    planner: Planner = field(default_factory=Planner)
    notifier: LocalNotifier = field(default_factory=LocalNotifier)
    placements: PlacementQueue = field(default_factory=PlacementQueue)

    def __post_init__(self) -> None:
        # A robot that reports its own changes (motion starts, next action, stops) tells the participant's page.
        if hasattr(self.robot, "on_change"):
            self.robot.on_change = self._robot_changed  # type: ignore[attr-defined]

    def _robot_changed(self, key: str) -> None:
        participant_id = participant_of_key(key)
        if participant_id is not None:
            self.notifier.publish(participant_id)

    @staticmethod
    def from_settings(settings: Settings, robot: Robot | None = None) -> "Context":
        """Open the database and its notifier; the robot is the one given (the app composes it) or else the trace
        robot."""
        if robot is None:
            robot = TraceRobot("dinner", settings.robot_seconds_per_object)
        return Context(Database(settings.database_url, busy_seconds=settings.database_busy_seconds), robot, settings,
                       notifier=make_notifier(settings.database_url))


def aware(value: datetime | None) -> datetime | None:
    """SQLite returns naive datetimes; every stored time is UTC."""
    if value is None or value.tzinfo is not None:
        return value
    return value.replace(tzinfo=timezone.utc)


def iso(value: datetime | None) -> str | None:
    value = aware(value)
    return None if value is None else value.isoformat()


def commit(s: Any) -> None:
    try:
        repo.commit(s)
    except repo.WriteConflict as exc:
        raise Conflict(f"a concurrent request changed the same data first; reload and retry ({exc})") from exc
