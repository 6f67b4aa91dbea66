"""The study server's MuJoCo robot (tableteach.robot.Robot and ViewingRobot): per key a MujocoWorld, a
viser SceneView started when a page asks for it, and a player thread that shows motions in real time.

Physics runs as soon as the server asks (a placement costs about 80 ms, in MuJoCo's C code), so a placement's
labels come back without waiting for the motion to be shown and no database transaction waits for
an animation; the view then plays the recorded frames (nobody watching: they fast-forward). The robot's
own executions are worked out whole (plan_execution), in robot worker processes when `workers` > 0
(tableteach.sim.worker_pool), and saved as a .viser file that the browser plays, so no process streams
them. Labels always come from MujocoWorld.labels(), MuJoCo's labeling function.
See docs/frontend.md.
"""

from __future__ import annotations

import logging
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

from ..core.clauses import humanize
from ..robot import ExecutionPlan, RobotActivity
from .motion_file import viser_path
from .physics import MujocoWorld
from .playback import play
from .recording import Recording
from .recordings import RecordingId, SavedRecording, save_recording
from .view import SceneView
from .work_out import StudioSource, work_out_execution
from .worker_pool import ExecutionWorkers, WorkerFailed

log = logging.getLogger(__name__)

Labels = frozenset[str]


def table_seed(key: str) -> int:
    """The start-pose jitter seed of a table: fixed per key, so a restarted server rebuilds the same scene."""
    return zlib.crc32(key.encode()) % (2**31)


class _Table:
    """One participant's table; `ops` serialises the robot's calls, `lock` guards the world and fields."""

    def __init__(self, key: str) -> None:
        self.key = key
        self.seed = table_seed(key)
        self.world = MujocoWorld(self.seed)
        self.view: SceneView | None = None
        self.ops = threading.Lock()
        self.lock = threading.RLock()
        self.active = False  # False until reset/place and after release: placed() says None
        self.on_click: Callable[[str], None] | None = None
        self.clicking = False
        self.pending: deque[tuple[str, Recording]] = deque()  # placements simulated but not yet shown
        self.action_ends: list[float] = []  # simulated time at which each action since the reset ended
        self.caption = ""
        self.player: threading.Thread | None = None
        self.stop = threading.Event()
        self.last_used = time.monotonic()
        self.speed = 1.0  # the study's playback rate, on top of the robot's own

    @property
    def moving(self) -> bool:
        return self.player is not None

    @property
    def watchers(self) -> int:
        return 0 if self.view is None else self.view.client_count


class MujocoRobot:
    """Tables keyed by the server's string; thread-safe; idle views are stopped after `idle_seconds`.

    Executions are worked out in `workers` worker processes, or in this process when it is 0.
    """

    def __init__(self, *, speed: float = 1.0, data_dir: Path | str = "var/data", idle_seconds: float = 600.0,
                 workers: int = 0) -> None:
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.0")
        self.speed = speed
        self.data_dir = Path(data_dir)
        self.idle_seconds = idle_seconds
        self._tables: dict[str, _Table] = {}
        self._lock = threading.Lock()
        self._reaper: threading.Thread | None = None
        self._closing = threading.Event()
        self._studio = StudioSource()  # executions worked out in this process (workers == 0)
        self._workers = ExecutionWorkers(workers) if workers > 0 else None
        self._plans: dict[tuple[str, tuple[str, ...], str, float], ExecutionPlan] = {}  # the last few: plan_execution
        self._preparing: dict[tuple[str, tuple[str, ...], str, float], Future[ExecutionPlan]] = {}
        self._prep_pool: ThreadPoolExecutor | None = None
        self.on_change: Callable[[str], None] | None = None  # told a table's key when its activity changes

    # -- Robot -------------------------------------------------------------------------------------
    def reset(self, key: str) -> Labels:
        """Everything back on Table A; the labels of the cleared table."""
        table = self._table(key)
        with table.ops:
            self._halt(table)
            with table.lock:
                self._clear(table)
                table.active = True
                labels = table.world.labels()
            self._refresh(table)
        return labels

    def place(self, key: str, obj: str) -> Labels:
        """Simulate placing `obj` now and return the labels; the view shows the motion afterwards."""
        table = self._table(key)
        with table.ops:
            with table.lock:
                table.active = True
                start = len(table.world.recording) - 1
                labels = table.world.place(obj)  # PlacementError (a ValueError) for an unknown or moved object
                table.action_ends.append(float(table.world.data.time))
                if table.watchers > 0:
                    table.pending.append((f"The robot is placing the {humanize(obj)}",
                                          table.world.recording.since(start)))
                else:
                    self._show_still(table)
            self._start_player(table)
            self._refresh(table)
        self._changed(table)
        return labels

    def placed(self, key: str) -> tuple[str, ...] | None:
        """Objects moved off Table A since the last reset, or None for a table the robot does not hold."""
        table = self._get(key)
        if table is None:
            return None
        with table.lock:
            return tuple(table.world.placed) if table.active else None

    def trace(self, key: str) -> tuple[Labels, ...] | None:
        """The labels after the last reset and after each placement since, as MuJoCo judged them (None as placed)."""
        table = self._get(key)
        if table is None:
            return None
        with table.lock:
            return tuple(table.world.trace) if table.active else None

    def prepare(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> Future[ExecutionPlan]:
        """plan_execution in the background: the plan already made, the one under way, or a new one."""
        memo = (key, tuple(events), name, speed)
        with self._lock:
            known = self._plans.get(memo)
            if known is not None and viser_path(self.data_dir, RecordingId.parse(name)).exists():
                done: Future[ExecutionPlan] = Future()
                done.set_result(known)
                return done
            if memo in self._preparing:
                return self._preparing[memo]
            if self._closing.is_set():
                raise RuntimeError("the robot is shutting down: expected no new executions")
            if self._prep_pool is None:
                self._prep_pool = ThreadPoolExecutor(max_workers=self._workers.size if self._workers else 1,
                                                     thread_name_prefix="robot-prepare")
            future = self._preparing[memo] = self._prep_pool.submit(self._work_out, key, tuple(events), name, speed)
            return future

    def plan_execution(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> ExecutionPlan:
        """Simulate the whole execution on a fresh copy of the table and save it (.npz, .json and a .viser file).

        Nothing is shown live: the browser plays the .viser file, at `speed` (the study's robot_speed) on top of
        the robot's own; the plan's action ends are divided alike, and the saved recording keeps real time. An
        execution already worked out (or being worked out, see prepare) is not simulated again.
        """
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.5")
        events = tuple(events)
        memo = (key, events, name, speed)
        with self._lock:
            known, preparing = self._plans.get(memo), self._preparing.get(memo)
        if known is not None and viser_path(self.data_dir, RecordingId.parse(name)).exists():
            return known
        if preparing is not None:
            try:
                return preparing.result()
            except Exception:  # noqa: BLE001 - worked out again below, where the error reaches the caller
                log.warning("preparing execution %s failed; working it out again", name, exc_info=True)
        return self._work_out(key, events, name, speed)

    def _work_out(self, key: str, events: tuple[str, ...], name: str, speed: float) -> ExecutionPlan:
        rid = RecordingId.parse(name)
        memo = (key, events, name, speed)
        try:
            return self._simulate(key, events, rid, memo, self.speed * speed)
        finally:
            with self._lock:
                self._preparing.pop(memo, None)

    def _simulate(self, key: str, events: tuple[str, ...], rid: RecordingId,
                  memo: tuple[str, tuple[str, ...], str, float], rate: float) -> ExecutionPlan:
        worked = None
        if self._workers is not None:
            try:
                worked = self._workers.run(self.data_dir, table_seed(key), events, rid, rate)
            except WorkerFailed:  # e.g. no process can be started: slower here, but the participant carries on
                log.warning("the robot workers failed on %s; working it out in the server process", rid.name,
                            exc_info=True)
        if worked is None:
            worked = work_out_execution(self._studio, self.data_dir, table_seed(key), events, rid, rate)
        with self._lock:
            if len(self._plans) >= 1024:
                self._plans.pop(next(iter(self._plans)))
            self._plans[memo] = worked
        return worked

    def release(self, key: str) -> None:
        """Forget the table's contents; its view (if any) stays up showing a cleared table."""
        table = self._get(key)
        if table is None:
            return
        with table.ops:
            self._halt(table)
            with table.lock:
                self._clear(table)
                table.active = False
                table.on_click = None
            self._refresh(table)
            if table.view is None:
                self._drop(key, table)

    def save_recording(self, key: str, name: str) -> None:
        """Save the motion since the last reset under data_dir (see tableteach.sim.recordings)."""
        rid = RecordingId.parse(name)
        table = self._get(key)
        if table is None:
            log.warning("no table %s to save %s from", key, name)
            return
        with table.lock:
            saved = SavedRecording(rid, table.world.recording, tuple(table.world.placed), tuple(table.world.trace),
                                   tuple(table.action_ends))
        save_recording(self.data_dir, saved)

    def close(self, key: str) -> None:
        """Stop the table's motion and view and forget it."""
        with self._lock:
            table = self._tables.pop(key, None)
        if table is not None:
            self._shut(table)

    def set_speed(self, key: str, speed: float) -> None:
        """Show this table's motions `speed` times faster (the study's setting; recordings keep real time)."""
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.5")
        self._table(key).speed = speed

    # -- ViewingRobot --------------------------------------------------------------------------------
    def open_view(self, key: str, on_click: Callable[[str], None] | None) -> int:
        """The table's viser port (started on first use); waiting objects report clicks to on_click."""
        table = self._table(key)
        with table.ops:
            if table.view is None:
                table.view = SceneView(table.world.model, clickable=(), on_click=lambda obj: self._clicked(table, obj))
                with table.lock:
                    self._show_still(table)
                    table.view.set_caption(table.caption)
            table.on_click = on_click
            table.last_used = time.monotonic()
            self._refresh(table)
            port = table.view.port
        self._ensure_reaper()
        return port

    def has_view(self, key: str) -> bool:
        """Whether the table's viser view is running."""
        with self._lock:
            table = self._tables.get(key)  # looking is not using: the idle clock keeps running
        return table is not None and table.view is not None

    def activity(self, key: str) -> RobotActivity | None:
        """Whether the robot moves, its caption, and how many browsers watch."""
        table = self._get(key)
        if table is None:
            return None
        busy = table.moving or table.clicking
        return RobotActivity(busy, table.caption if busy else "", table.watchers)

    def scene(self, key: str) -> tuple[MujocoWorld, SceneView | None] | None:
        """The table's world and view, for tests and tools that look (never move anything through these)."""
        with self._lock:
            table = self._tables.get(key)  # looking is not using: the idle clock keeps running
        return None if table is None else (table.world, table.view)

    def shutdown(self) -> None:
        """Close every table (server shutdown)."""
        self._closing.set()
        with self._lock:
            tables = list(self._tables.values())
            self._tables.clear()
        for table in tables:
            self._shut(table)
        if self._prep_pool is not None:
            self._prep_pool.shutdown(wait=True, cancel_futures=True)
        if self._workers is not None:
            self._workers.close()
        self._studio.close()

    # -- internals -----------------------------------------------------------------------------------
    def _get(self, key: str) -> _Table | None:
        with self._lock:
            table = self._tables.get(key)
        if table is not None:
            table.last_used = time.monotonic()
        return table

    def _table(self, key: str) -> _Table:
        with self._lock:
            table = self._tables.get(key)
            if table is None:
                table = self._tables[key] = _Table(key)
        table.last_used = time.monotonic()
        return table

    def _drop(self, key: str, table: _Table) -> None:
        with self._lock:
            if self._tables.get(key) is table:
                del self._tables[key]
        table.world.close()

    def _shut(self, table: _Table) -> None:
        with table.ops:
            self._halt(table)
            if table.view is not None:
                table.view.close()
                table.view = None
            table.world.close()

    def _clear(self, table: _Table) -> None:
        """Reset the world and the table's bookkeeping (caller holds table.lock, player halted)."""
        table.world.reset(table.seed)
        table.pending.clear()
        table.action_ends = []
        table.caption = ""
        self._show_still(table)

    def _show_still(self, table: _Table) -> None:
        """Show the simulated state as it is now (caller holds table.lock)."""
        if table.view is not None:
            table.view.set_poses(table.world.bodies, table.world.body_poses())

    def _halt(self, table: _Table) -> None:
        """Stop the player thread (caller holds table.ops but not table.lock: the player takes it)."""
        player = table.player
        if player is not None:
            table.stop.set()
            player.join()
        table.stop.clear()
        table.caption = ""
        if table.view is not None:
            table.view.set_caption("")

    def _start_player(self, table: _Table) -> None:
        """Start the player unless it runs (it decides to end under table.lock, so nothing is left unshown)."""
        with table.lock:
            if table.player is not None:
                return
            if not table.pending:
                return
            table.player = threading.Thread(target=self._play, args=(table,), name=f"robot-{table.key}", daemon=True)
            table.player.start()


    def _play(self, table: _Table) -> None:
        """Player thread: show each motion at wall-clock speed while watched, else jump to its end."""
        try:
            while not table.stop.is_set():
                with table.lock:
                    if not table.pending:  # every placement simulated so far has been shown
                        table.player = None
                        break
                    caption, segment = table.pending.popleft()
                    table.caption = caption
                self._changed(table)
                view = table.view
                if view is not None:
                    view.set_caption(caption)
                    if view.client_count > 0:
                        play(segment, view, speed=self.speed * table.speed, stop=table.stop)
                if table.stop.is_set():
                    break
                with table.lock:
                    if view is not None:
                        view.set_poses(segment.bodies, segment.poses[-1])
        except Exception:
            log.exception("robot %s failed while moving", table.key)
        finally:
            with table.lock:
                if table.player is threading.current_thread():
                    table.player = None
                table.caption = ""
            if table.view is not None:
                table.view.set_caption("")
            self._refresh(table)
            self._changed(table)

    def _changed(self, table: _Table) -> None:
        """Tell the server that this table's activity changed (it pushes the news to the participant's page)."""
        callback = self.on_change
        if callback is None:
            return
        try:
            callback(table.key)
        except Exception:
            log.exception("change notice for table %s failed", table.key)

    def _refresh(self, table: _Table) -> None:
        """Make exactly the objects a participant may click now clickable."""
        view = table.view
        if view is None:
            return
        with table.lock:
            idle = not table.pending and not table.clicking
            want = set()
            if table.on_click is not None and idle and table.player is None:
                want = {o for o in table.world.objects if o not in table.world.placed}
        for obj in table.world.objects:
            view.set_clickable(obj, obj in want)

    def _clicked(self, table: _Table, obj: str) -> None:
        """A click on a waiting object (viser's thread): hand it to the server's callback, one at a time."""
        with table.lock:
            callback = table.on_click
            if callback is None or table.clicking:
                return
            table.clicking = True
            if table.player is None:
                table.caption = f"The robot is placing the {humanize(obj)}"
        self._refresh(table)
        self._changed(table)
        try:
            callback(obj)
        except Exception:
            log.exception("click on %s at table %s failed", obj, table.key)
        finally:
            with table.lock:
                table.clicking = False
                if table.player is None:
                    table.caption = ""
            self._refresh(table)
            self._changed(table)

    def _ensure_reaper(self) -> None:
        with self._lock:
            if self._reaper is not None and self._reaper.is_alive():
                return
            self._reaper = threading.Thread(target=self._reap, name="robot-view-reaper", daemon=True)
            self._reaper.start()

    def _reap(self) -> None:
        """Stop views nobody has watched or used for idle_seconds; end once no view is left."""
        interval = max(0.05, min(30.0, self.idle_seconds / 4))
        while not self._closing.wait(interval):
            now = time.monotonic()
            with self._lock:
                tables = [(k, t) for k, t in self._tables.items() if t.view is not None]
            if not tables:
                return
            for key, table in tables:
                if table.watchers > 0 or table.moving:
                    table.last_used = now
                elif now - table.last_used > self.idle_seconds:
                    log.info("stopping the idle view of table %s", key)
                    with table.ops:
                        if table.view is not None:
                            table.view.close()
                            table.view = None
                    if not table.active:
                        self._drop(key, table)
