"""The request context shared by every service (settings, database, robot, tab leases) and small helpers."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from collections.abc import Callable
from typing import Any

from ..config import Settings
from ..version import app_version as app_version  # re-exported: the services name it so
from ..db import repository as repo
from ..db.engine import Database
from ..errors import Conflict
from ..robot import Robot, TraceRobot
from ..recording_store import FileRecordingStore, RecordingStore
from .notify import LocalNotifier, make_notifier, participant_of_key
from .planning import Planner
from .runtime import Runtime
from .study_objects import scene_lookup


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


def default_runtime(robot_workers: int = 1) -> Runtime:
    """A runtime with every background job's handler (services.background), and a runner of every kind per robot
    worker (the slow jobs wait for one)."""
    from .background import HANDLERS  # background builds on the actions, which build on this module

    return Runtime(HANDLERS, slow_runners=max(1, robot_workers))


@dataclass
class Context:
    """What every action needs: the database, the robot, the recording store and the settings, plus tab leases,
    the planner's cache, the page notifier and the runtime that owns every thread (services.runtime)."""

    db: Database
    robot: Robot
    settings: Settings
    tabs: TabLeases = field(default_factory=TabLeases)
    planner: Planner = field(default_factory=Planner)
    notifier: LocalNotifier = field(default_factory=LocalNotifier)
    runtime: Runtime = field(default_factory=default_runtime)
    recordings: RecordingStore | None = None

    def __post_init__(self) -> None:
        if self.recordings is None:
            self.recordings = FileRecordingStore(self.settings.data_dir)
        # The robot reports its own changes (motion starts and ends): the participant's page is told.
        self.robot.on_change = self._robot_changed
        self.robot.scene_of = scene_lookup(self.db)  # a table's objects: its study's own, or the dinner table

    def _robot_changed(self, key: str) -> None:
        participant_id = participant_of_key(key)
        if participant_id is not None:
            self.notifier.publish(participant_id)

    @property
    def store(self) -> RecordingStore:
        """The recording store (set in __post_init__)."""
        assert self.recordings is not None
        return self.recordings

    def start(self) -> None:
        """Start the runtime's threads (the app's start-up)."""
        self.runtime.sweep_seconds = self.settings.timeout_sweep_seconds
        self.runtime.start(self)

    def close(self) -> None:
        """Stop the runtime (handlers under way end; unfinished jobs stay stored), the notifier and the database."""
        self.runtime.stop()
        self.notifier.close()
        self.db.dispose()

    @staticmethod
    def from_settings(settings: Settings, robot: Robot | None = None,
                      recordings: RecordingStore | Callable[[Database], RecordingStore] | None = None) -> "Context":
        """Open the database and its notifier; the robot and recording store are the ones given (the app composes
        them; a store that needs the database is given as a function of it), or else the trace robot and files."""
        if robot is None:
            robot = TraceRobot("dinner", settings.robot_seconds_per_object)
        db = Database(settings.database_url, busy_seconds=settings.database_busy_seconds)
        store = recordings(db) if callable(recordings) else recordings
        return Context(db, robot, settings, notifier=make_notifier(settings.database_url), recordings=store,
                       runtime=default_runtime(settings.robot_workers))


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
