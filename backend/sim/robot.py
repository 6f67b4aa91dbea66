"""The study server's MuJoCo robot (tableteach.robot.Robot): per key a MujocoWorld, shown to the participant's
browsers by the process's one viser server (ViewHub, a scene per browser), with one animator thread for
every table's motion.

Physics runs as soon as the server asks (a placement costs about 80 ms, in MuJoCo's C code, on a runtime job
thread), so a placement's labels come back without waiting for the motion to be shown; the animator then
plays the recorded frames to the browsers watching that table (nobody watching: the table jumps to its end
pose). The robot's own executions are worked out whole (plan_execution), in robot worker processes when
`workers` > 0 (tableteach.sim.worker_pool), and saved as a .viser file that the browser plays, so no
process streams them. Labels always come from MujocoWorld.labels(), MuJoCo's labeling function.
Every table of a task starts alike (table_seed), so motion is simulated once: placements seen before come from
clips (tableteach.sim.clips, in memory and as files every process shares) and executions seen before are
linked to the step from a shared motion (tableteach.sim.motion_store).
Threads: only the animator, started by start() and stopped by shutdown() (the runtime calls both); viser's
own threads belong to its server. See docs/concurrency.md.
"""

from __future__ import annotations

import logging
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import mujoco

from ..core.clauses import humanize
from ..recording_store import RecordingId
from ..robot import ExecutionPlan, RobotActivity, ViewAddress
from ..scenes.spec import SceneSpec
from .clips import CACHE_FOLDER, CLIP_CACHE_BYTES, ClipCache, clip_folder, warm
from .motion_file import viser_path
from .physics import MujocoWorld
from .recording import Recording
from .recordings import SavedRecording, save_recording
from .scene import SCENE_XML, scene_layout
from .scene_mjcf import SCENE_FOLDER, scene_path
from .view_hub import ViewHub
from .work_out import StudioSource, known_execution, work_out_execution
from .worker_pool import ExecutionWorkers, WorkerFailed

log = logging.getLogger(__name__)

Labels = frozenset[str]
IDLE_WORLD_SECONDS = 120.0  # a table unused this long frees its simulation (rebuilt from the stored placements)
REAP_EVERY_SECONDS = 5.0


def table_seed(key: str) -> int:
    """The start-pose jitter seed of a table: the same for every participant's table of one task (the key's part
    after its last "/", the task index: services.state.table_key) and fixed across restarts, so a restarted
    server rebuilds the same scene and the same table and plan give the same motion, which participants then
    share (placement clips, shared recordings)."""
    return zlib.crc32(f"task-{key.rsplit('/', 1)[-1]}".encode()) % (2**31)


def warm_tables(data_dir: Path | str, tasks: Sequence[int]) -> dict[str, int]:
    """Simulate, once per data folder, every placement the tables of these task indices can ask for (their clip
    files), so that no participant's placement or execution waits for its physics; what was simulated now."""
    cache = ClipCache(folder=clip_folder(data_dir))
    simulated = known = 0
    for task in tasks:
        new, had = warm(cache, table_seed(f"0/{task}"))
        simulated, known = simulated + new, known + had
    return {"simulated": simulated, "already_kept": known}


@dataclass
class _Motion:
    """A placement's recorded frames being shown: caption, frames, and when the showing started and ends."""

    caption: str
    segment: Recording
    started: float = 0.0
    ends: float = 0.0


class _Table:
    """One participant's table; `lock` guards the world and every field. Its MujocoWorld (a few MB) exists only
    while the table is in use: a view needs none, and an idle table's world is dropped (rebuilt on its next use
    from the stored placements)."""

    def __init__(self, key: str, scene: Path) -> None:
        self.key = key
        self.scene = scene  # the dinner scene, or one generated from the study's objects
        self.seed = table_seed(key)
        self._world: MujocoWorld | None = None
        self.last_used = time.monotonic()
        self.lock = threading.RLock()
        self.active = False  # False until reset/place and after release: placed() says None
        self.on_click: Callable[[str], None] | None = None
        self.clicking = False
        self.pending: deque[_Motion] = deque()  # placements simulated but not yet shown, the first one showing
        self.action_ends: list[float] = []  # simulated time at which each action since the reset ended
        self.speed = 1.0  # the study's playback rate, on top of the robot's own

    @property
    def world(self) -> MujocoWorld:
        """The table's simulation, made on first use (caller holds lock)."""
        self.last_used = time.monotonic()
        if self._world is None:
            self._world = MujocoWorld(self.seed, self.scene)
        return self._world

    @property
    def has_world(self) -> bool:
        return self._world is not None

    def drop_world(self) -> None:
        """Free the simulation (caller holds lock); placed() says None until the table is used again."""
        if self._world is not None:
            self._world.close()
            self._world = None
        self.active = False
        self.action_ends = []

    @property
    def moving(self) -> bool:
        return bool(self.pending)

    @property
    def caption(self) -> str:
        if self.pending:
            return self.pending[0].caption
        return ""


class MujocoRobot:
    """Tables keyed by the server's string; thread-safe. Executions are worked out in `workers` worker
    processes, or in this process when it is 0."""

    works_in_background = True
    shows_view = True

    def __init__(self, *, speed: float = 1.0, data_dir: Path | str = "var/data", workers: int = 0,
                 idle_seconds: float = IDLE_WORLD_SECONDS, clip_bytes: int = CLIP_CACHE_BYTES) -> None:
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.0")
        self.speed = speed
        self.data_dir = Path(data_dir)
        self.idle_seconds = idle_seconds
        self._scratch: dict[Path, MujocoWorld] = {}  # start poses of tables that have no world (first views)
        self._tables: dict[str, _Table] = {}
        self._scenes: dict[str, Path] = {}  # each key's scene, once asked (scene_of)
        self._lock = threading.Lock()
        self._studio = StudioSource()  # executions worked out in this process (workers == 0)
        self.clips = ClipCache(clip_bytes, clip_folder(self.data_dir))  # placements simulated once, by any process
        self._workers = ExecutionWorkers(workers) if workers > 0 else None
        self._plans: dict[tuple[str, tuple[str, ...], str, float], ExecutionPlan] = {}  # the last few
        self._hub: ViewHub | None = None
        self._animator: threading.Thread | None = None
        self._animate = threading.Event()
        self._closing = threading.Event()
        self.on_change: Callable[[str], None] | None = None  # told a table's key when its activity changes
        self.scene_of: Callable[[str], SceneSpec | None] | None = None  # a key's own objects (None: the dinner)

    # -- life --------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the animator thread (the runtime calls this once)."""
        with self._lock:
            if self._animator is None and not self._closing.is_set():
                self._animator = threading.Thread(target=self._animate_loop, name="robot-animator", daemon=True)
                self._animator.start()

    def shutdown(self) -> None:
        """Close every table, the view server, the animator and the worker processes (server shutdown)."""
        self._closing.set()
        self._animate.set()
        with self._lock:
            tables = list(self._tables.values())
            self._tables.clear()
            hub, self._hub = self._hub, None
            animator = self._animator
        if animator is not None:
            animator.join(timeout=5)
        for table in tables:
            with table.lock:
                table.drop_world()
        self.clips.clear()
        if hub is not None:
            hub.close()
        if self._workers is not None:
            self._workers.close()
        self._studio.close()

    # -- Robot -------------------------------------------------------------------------------------
    def reset(self, key: str) -> Labels:
        """Everything back on Table A; the labels of the cleared table."""
        table = self._table(key)
        with table.lock:
            self._clear(table)
            table.active = True
            labels = table.world.labels()
        self._refresh(table)
        self._changed(table)
        return labels

    def place(self, key: str, obj: str) -> Labels:
        """Simulate placing `obj` now and return the labels; the browsers watching are shown the motion."""
        table = self._table(key)
        with table.lock:
            table.active = True
            start = len(table.world.recording) - 1
            labels = self.clips.place(table.world, obj)  # PlacementError (a ValueError): unknown or moved object
            table.action_ends.append(float(table.world.data.time))
            if self._watchers(key) > 0:
                table.pending.append(_Motion(f"The robot is placing the {humanize(obj)}",
                                             table.world.recording.since(start)))
            else:
                self._show_still(table)
        if table.pending:
            self._animate.set()
        self._refresh(table)
        self._changed(table)
        return labels

    def restore(self, key: str, placed: Sequence[str]) -> None:
        """Rebuild the table holding exactly these placements (simulated again: physics is deterministic), and
        show the browsers the result without the motion."""
        table = self._table(key)
        with table.lock:
            self._clear(table)
            table.active = True
            for obj in placed:
                self.clips.place(table.world, obj)
                table.action_ends.append(float(table.world.data.time))
            self._show_still(table)
        self._refresh(table)
        self._changed(table)

    def placed(self, key: str) -> tuple[str, ...] | None:
        """Objects moved off Table A since the last reset, or None for a table the robot does not hold."""
        table = self._get(key)
        if table is None:
            return None
        with table.lock:
            return tuple(table.world.placed) if table.active and table.has_world else None

    def trace(self, key: str) -> tuple[Labels, ...] | None:
        """The labels after the last reset and after each placement since, as MuJoCo judged them (None as placed)."""
        table = self._get(key)
        if table is None:
            return None
        with table.lock:
            return tuple(table.world.trace) if table.active and table.has_world else None

    def plan_execution(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> ExecutionPlan:
        """Simulate the whole execution on a fresh copy of the table and save it (.npz, .json and a .viser file).

        Nothing is shown live: the browser plays the .viser file, at `speed` (the study's robot_speed) on top of
        the robot's own; the plan's action ends are divided alike, and the saved recording keeps real time. An
        execution already worked out, for this step or for anyone's with the same table, objects and rate (a
        shared motion, tableteach.sim.motion_store), is not simulated again.
        """
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.5")
        events = tuple(events)
        memo = (key, events, name, speed)
        rid = RecordingId.parse(name)
        with self._lock:
            known = self._plans.get(memo)
        if known is not None and viser_path(self.data_dir, rid).exists():
            return known
        rate = self.speed * speed
        seed = table_seed(key)
        scene = self._scene(key)
        worked = known_execution(self.data_dir, seed, events, rid, rate, scene)  # no worker woken for a shared motion
        if worked is None and self._workers is not None:
            try:
                worked = self._workers.run(self.data_dir, seed, events, rid, rate, scene)
            except WorkerFailed:  # e.g. no process can be started: slower here, but the participant carries on
                log.warning("the robot workers failed on %s; working it out in the server process", rid.name,
                            exc_info=True)
        if worked is None:
            worked = work_out_execution(self._studio, self.data_dir, seed, events, rid, rate, self.clips, scene)
        with self._lock:
            if len(self._plans) >= 1024:
                self._plans.pop(next(iter(self._plans)))
            self._plans[memo] = worked
        return worked

    def release(self, key: str) -> None:
        """Forget the table's contents; the browsers showing it see a cleared table."""
        table = self._get(key)
        if table is None:
            return
        with table.lock:
            table.pending.clear()
            table.drop_world()
            table.on_click = None
        self._show_start(table)
        self._refresh(table)
        self._changed(table)

    def save_recording(self, key: str, name: str) -> None:
        """Save the motion since the last reset under data_dir (see tableteach.sim.recordings)."""
        rid = RecordingId.parse(name)
        table = self._get(key)
        if table is None or not table.has_world:
            log.warning("no table %s to save %s from", key, name)
            return
        with table.lock:
            saved = SavedRecording(rid, table.world.recording, tuple(table.world.placed), tuple(table.world.trace),
                                   tuple(table.action_ends))
        save_recording(self.data_dir, saved)

    def close(self, key: str) -> None:
        """Forget the table (its browsers keep their scene until they leave or reload)."""
        with self._lock:
            table = self._tables.pop(key, None)
            self._scenes.pop(key, None)
            hub = self._hub
        if hub is not None:
            hub.drop(key)
        if table is not None:
            with table.lock:
                table.pending.clear()
                table.drop_world()

    def set_speed(self, key: str, speed: float) -> None:
        """Show this table's motions `speed` times faster (the study's setting; recordings keep real time)."""
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.5")
        self._table(key).speed = speed

    # -- views -------------------------------------------------------------------------------------
    def open_view(self, key: str, on_click: Callable[[str], None] | None) -> ViewAddress:
        """Where the proxy connects a browser to this table's view (the process's one viser server); clicks on
        waiting objects call on_click, which must only queue them."""
        table = self._table(key)
        with table.lock:
            table.on_click = on_click
        hub = self._ensure_hub()
        address = ViewAddress(hub.port(), "/" + hub.ticket(key))
        self._refresh(table)
        return address

    def has_view(self, key: str) -> bool:
        """Whether a browser shows the table now."""
        return self._watchers(key) > 0

    def activity(self, key: str) -> RobotActivity | None:
        """Whether the robot moves, its caption, and how many browsers watch."""
        table = self._get(key)
        if table is None:
            return None
        with table.lock:
            busy = table.moving or table.clicking
            caption = table.caption if table.moving else (table.caption or "")
        return RobotActivity(busy, caption if busy else "", self._watchers(key))

    def view_count(self) -> int:
        """Browsers connected to any table of this process."""
        hub = self._hub
        return 0 if hub is None else hub.views()

    def view_clients(self, key: str) -> list[object]:
        """The viser clients showing this table (for tests and tools that look, e.g. at a browser's camera)."""
        hub = self._hub
        return [] if hub is None else list(hub.clients(key))

    def scene(self, key: str) -> MujocoWorld | None:
        """The table's world, for tests and tools that look (never move anything through it)."""
        with self._lock:
            table = self._tables.get(key)
        return None if table is None else table._world

    def clicked(self, key: str, obj: str) -> None:
        """A click on a waiting object (a viser thread): mark the table busy and hand it on to be queued."""
        table = self._get(key)
        if table is None:
            return
        with table.lock:
            callback = table.on_click
            placed = table.world.placed if table.has_world and table.active else ()
            if callback is None or table.clicking or table.moving or obj in placed:
                return
            table.clicking = True
        self._refresh(table)
        self._changed(table)
        try:
            callback(obj)
        except Exception:
            log.exception("click on %s at table %s could not be queued", obj, table.key)
            self.click_done(key)

    def click_done(self, key: str) -> None:
        """The queued click has been carried out (or refused): the table takes clicks again."""
        table = self._get(key)
        if table is None:
            return
        with table.lock:
            table.clicking = False
        self._refresh(table)
        self._changed(table)

    # -- internals -----------------------------------------------------------------------------------
    def _ensure_hub(self) -> ViewHub:
        with self._lock:
            if self._hub is None:
                if self._closing.is_set():
                    raise RuntimeError("the robot is shutting down: expected no new views")
                self._hub = ViewHub(MujocoWorld(0).model, on_join=self._joined, on_click=self.clicked,
                                    on_leave=lambda key: None)
            return self._hub

    def _watchers(self, key: str) -> int:
        hub = self._hub
        return 0 if hub is None else hub.watchers(key)

    def _joined(self, key: str) -> tuple[Sequence[str], np.ndarray, str, frozenset[str], mujoco.MjModel] | None:
        """What a browser joining this table is shown first: the table as it is now (motions under way skipped), and
        the model whose moving bodies it shows."""
        table = self._table(key)
        with table.lock:
            if table.has_world:
                world = table.world
                return world.bodies, world.body_poses(), table.caption, self._clickable(table), world.model
            bodies, poses, model = self._start_poses(table.seed, table.scene)
            return bodies, poses, table.caption, self._clickable(table), model

    def _show_start(self, table: _Table) -> None:
        """Show the browsers of a table without a world its cleared state."""
        hub = self._hub
        if hub is not None and hub.watchers(table.key):
            bodies, poses, _model = self._start_poses(table.seed, table.scene)
            hub.show(table.key, bodies, poses)
            hub.set_caption(table.key, "")

    def _start_poses(self, seed: int, scene: Path) -> tuple[Sequence[str], np.ndarray, mujoco.MjModel]:
        """A cleared table's poses for this seed, from the robot's scratch world of the scene (no world per view)."""
        with self._lock:
            scratch = self._scratch.get(scene)
            if scratch is None:
                scratch = self._scratch[scene] = MujocoWorld(seed, scene)
            else:
                scratch.reset(seed)
            return scratch.bodies, scratch.body_poses(), scratch.model

    def _get(self, key: str) -> _Table | None:
        with self._lock:
            return self._tables.get(key)

    def _table(self, key: str) -> _Table:
        with self._lock:
            table = self._tables.get(key)
        if table is not None:
            return table
        scene = self._scene(key)  # may read the database: outside the robot's lock
        with self._lock:
            return self._tables.setdefault(key, _Table(key, scene))

    def _scene(self, key: str) -> Path:
        """The key's scene file: the dinner table, or the one generated from its study's objects (asked once)."""
        with self._lock:
            known = self._scenes.get(key)
        if known is not None:
            return known
        spec = None if self.scene_of is None else self.scene_of(key)
        scene = SCENE_XML if spec is None else scene_path(spec, self.data_dir / CACHE_FOLDER / SCENE_FOLDER)
        with self._lock:
            self._scenes[key] = scene
        return scene

    def _clear(self, table: _Table) -> None:
        """Reset the world and the table's bookkeeping (caller holds table.lock)."""
        table.world.reset(table.seed)
        table.pending.clear()
        table.action_ends = []
        self._show_still(table)

    def _show_still(self, table: _Table) -> None:
        """Show the simulated state as it is now (caller holds table.lock)."""
        hub = self._hub
        if hub is not None and table.has_world:
            hub.show(table.key, table.world.bodies, table.world.body_poses())
            hub.set_caption(table.key, table.caption)

    def _clickable(self, table: _Table) -> frozenset[str]:
        """The objects a participant may click now (caller holds table.lock)."""
        if table.on_click is None or table.pending or table.clicking:
            return frozenset()
        placed = set(table.world.placed) if table.has_world and table.active else set()
        return frozenset(o for o in scene_layout(table.scene).objects if o not in placed)

    def _refresh(self, table: _Table) -> None:
        """Make exactly the objects a participant may click now clickable."""
        hub = self._hub
        if hub is None:
            return
        with table.lock:
            want = self._clickable(table)
        hub.set_clickable(table.key, want)

    def _changed(self, table: _Table) -> None:
        """Tell the server that this table's activity changed (it pushes the news to the participant's page)."""
        callback = self.on_change
        if callback is None:
            return
        try:
            callback(table.key)
        except Exception:
            log.exception("change notice for table %s failed", table.key)

    def _animate_loop(self) -> None:
        """The animator: starts each moving table's next motion (sent once to its browsers, which play it on their
        own clock), ends it when its time is up; now and then frees the simulations of tables left idle."""
        reaped = time.monotonic()
        while not self._closing.is_set():
            self._animate.clear()  # a motion queued from here on wakes the wait below
            now = time.monotonic()
            if now - reaped > REAP_EVERY_SECONDS:
                self._reap_idle()
                reaped = now
            with self._lock:
                moving = [t for t in self._tables.values() if t.pending]
            wake = now + REAP_EVERY_SECONDS
            for table in moving:
                try:
                    due = self._advance(table, now)
                except Exception:  # noqa: BLE001 - one table's failure must not freeze the others
                    log.exception("robot %s failed while moving", table.key)
                    with table.lock:
                        table.pending.clear()
                    continue
                if due is not None:
                    wake = min(wake, due)
            self._animate.wait(max(0.0, wake - time.monotonic()))

    def _reap_idle(self) -> None:
        """Free the worlds of tables unused for idle_seconds (the stored placements rebuild them when needed)."""
        now = time.monotonic()
        with self._lock:
            tables = list(self._tables.values())
        for table in tables:
            with table.lock:
                if (table.has_world and not table.pending and not table.clicking
                        and now - table.last_used > self.idle_seconds):
                    log.debug("freeing the idle simulation of table %s", table.key)
                    table.drop_world()

    def _advance(self, table: _Table, now: float) -> float | None:
        """Start the table's current motion (its browsers are sent it to play) or, its time up, end it and show its
        last frame; when the animator should look at the table again (None: nothing is moving)."""
        hub = self._hub
        with table.lock:
            if not table.pending:
                return None
            motion = table.pending[0]
            segment = motion.segment
            first = motion.started == 0.0
            if first:
                rate = self.speed * table.speed
                motion.started, motion.ends = now, now + segment.duration / rate
                if hub is not None:
                    hub.set_caption(table.key, motion.caption)
                    hub.play(table.key, segment.bodies, (segment.times - segment.times[0]) / rate, segment.poses)
            ended = now >= motion.ends or hub is None or hub.watchers(table.key) == 0
            if ended:
                table.pending.popleft()
                if hub is not None:  # browsers that joined during the motion have not seen it end
                    hub.show(table.key, segment.bodies, segment.poses[-1])
                    hub.set_caption(table.key, table.caption)
            due = now if table.pending and ended else (None if ended else motion.ends)
        if first or ended:
            self._refresh(table)
            self._changed(table)
        return due
