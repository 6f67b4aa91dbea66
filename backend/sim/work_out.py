"""Working a robot execution out whole: simulate it on a fresh table, save its recording and its .viser file.

Pure given (table seed, events, rate): any process, or a robot worker process (tableteach.sim.execution_worker),
computes the same plan and the same files, so an execution worked out before (by any participant, in any
process) is not simulated again: its shared motion (tableteach.sim.motion_store) is linked to the step.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path

from ..core.clauses import humanize
from ..robot import ExecutionPlan
from .clips import ClipCache
from .motion_file import Studio
from .motion_store import MotionStore, motion_digest
from .physics import MujocoWorld
from .recordings import RecordingId, SavedRecording
from .scene import SCENE_XML, scene_layout
from .world import check_sequence


def captions(events: Sequence[str]) -> list[str]:
    """What the view says while each object is placed."""
    return [f"The robot is placing the {humanize(obj)} ({i + 1} of {len(events)})" for i, obj in enumerate(events)]


def execution_digest(seed: int, events: Sequence[str], rate: float, scene: Path = SCENE_XML) -> str:
    """The name of this execution's shared motion."""
    return motion_digest(scene, seed, events, rate, captions(events))


def known_execution(data_dir: Path, seed: int, events: Sequence[str], rid: RecordingId,
                    rate: float, scene: Path = SCENE_XML) -> ExecutionPlan | None:
    """The plan of an execution worked out before, its motion given to `rid`; None if it never was."""
    check_sequence(tuple(events), scene_layout(scene).objects)
    return MotionStore(data_dir).give(execution_digest(seed, events, rate, scene), rid)


def work_out_execution(studio_of: StudioSource, data_dir: Path, seed: int, events: Sequence[str],
                       rid: RecordingId, rate: float, clips: ClipCache | None = None,
                       scene: Path = SCENE_XML) -> ExecutionPlan:
    """Simulate `events` on a table of `scene` started from `seed` (placements in `clips` from there), save the
    recording and a .viser file played at `rate`; an execution worked out before is only linked to `rid`."""
    events = tuple(events)
    known = known_execution(data_dir, seed, events, rid, rate, scene)  # refuses a bad sequence before anything moves
    if known is not None:
        return known
    world = MujocoWorld(seed, scene)
    try:
        check_sequence(events, world.objects)
        start = float(world.data.time)
        starts, ends = [], []
        for obj in events:
            starts.append(float(world.data.time))
            if clips is None:
                world.place(obj)
            else:
                clips.place(world, obj)
            ends.append(float(world.data.time))
        recording = world.recording
        saved = SavedRecording(rid, recording, tuple(world.placed), tuple(world.trace), tuple(ends))
        timed = list(zip(starts, captions(events), strict=True))
        playable = studio_of(world).render(recording, timed, speed=rate)
        plan = ExecutionPlan(events, tuple(world.trace), tuple((end - start) / rate for end in ends), viewable=True)
        MotionStore(data_dir).keep(execution_digest(seed, events, rate, scene), saved, playable, plan)
        return plan
    finally:
        world.close()


class StudioSource:
    """A process's Studio per scene, each made on first use from the first world of that scene."""

    def __init__(self) -> None:
        self._studios: dict[str, Studio] = {}
        self._lock = threading.Lock()

    def __call__(self, world: MujocoWorld) -> Studio:
        with self._lock:
            studio = self._studios.get(world.scene)
            if studio is None:
                studio = self._studios[world.scene] = Studio(world.model)
            return studio

    def close(self) -> None:
        """Forget the studios (each one's hidden viser server was closed once it had its scene's snapshot)."""
        with self._lock:
            studios, self._studios = list(self._studios.values()), {}
        for studio in studios:
            studio.close()
