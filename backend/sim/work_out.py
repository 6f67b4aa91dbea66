"""Working a robot execution out whole: simulate it on a fresh table, save its recording and its .viser file.

Pure given (table seed, events): any process, or a robot worker process (tableteach.sim.execution_worker),
computes the same plan and the same files.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path

from ..core.clauses import humanize
from ..robot import ExecutionPlan
from .motion_file import Studio, viser_path, write_atomically
from .physics import MujocoWorld
from .recordings import RecordingId, SavedRecording, save_recording
from .world import check_sequence


def work_out_execution(studio_of: StudioSource, data_dir: Path, seed: int, events: Sequence[str],
                       rid: RecordingId, rate: float) -> ExecutionPlan:
    """Simulate `events` on a table started from `seed`, save the recording and a .viser file played at `rate`."""
    events = tuple(events)
    world = MujocoWorld(seed)
    try:
        check_sequence(events, world.objects)  # refuse the whole request before anything moves
        start = float(world.data.time)
        starts, ends = [], []
        for obj in events:
            starts.append(float(world.data.time))
            world.place(obj)
            ends.append(float(world.data.time))
        recording = world.recording
        save_recording(data_dir, SavedRecording(rid, recording, tuple(world.placed), tuple(world.trace), tuple(ends)))
        captions = [(t0, f"The robot is placing the {humanize(obj)} ({i + 1} of {len(events)})")
                    for i, (t0, obj) in enumerate(zip(starts, events, strict=True))]
        write_atomically(viser_path(data_dir, rid), studio_of(world).render(recording, captions, speed=rate))
        return ExecutionPlan(events, tuple(world.trace), tuple((end - start) / rate for end in ends), viewable=True)
    finally:
        world.close()


class StudioSource:
    """The one Studio of a process, made on first use from the first world's model."""

    def __init__(self) -> None:
        self._studio: Studio | None = None
        self._lock = threading.Lock()

    def __call__(self, world: MujocoWorld) -> Studio:
        with self._lock:
            if self._studio is None:
                self._studio = Studio(world.model)
            return self._studio

    def close(self) -> None:
        """Stop the studio's hidden viser server, if one was started."""
        with self._lock:
            if self._studio is not None:
                self._studio.close()
                self._studio = None
