"""Play poses into a view at wall-clock speed (sleeps between frames, skips frames when late)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable, Sequence

import numpy as np

from .recording import Recording
from .view import SceneView


def play(recording: Recording, view: SceneView, *, speed: float = 1.0, stop: threading.Event | None = None) -> int:
    """Push a recording's frames at their recorded times divided by `speed`; return frames shown."""
    return play_frames(recording.bodies, zip(recording.times, recording.poses, strict=True), view,
                       speed=speed, stop=stop)


def play_frames(
    bodies: Sequence[str],
    frames: Iterable[tuple[float, np.ndarray]],
    view: SceneView,
    *,
    speed: float = 1.0,
    stop: threading.Event | None = None,
) -> int:
    """Push (time, poses) frames, which may be computed lazily, at wall-clock pace; return frames shown.

    When the process falls behind, a frame whose successor is already due is skipped, so an
    overloaded server shows the motion at real speed with fewer frames rather than in slow motion.
    """
    if speed <= 0:
        raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.0")
    stop = stop or threading.Event()
    stream = iter(frames)
    current = next(stream, None)
    if current is None:
        return 0
    start_wall, start_sim = time.perf_counter(), float(current[0])

    def due(frame: tuple[float, np.ndarray]) -> float:
        return start_wall + (float(frame[0]) - start_sim) / speed

    shown = 0
    while current is not None:
        upcoming = next(stream, None)  # computed now, while there is time before `current` is due
        delay = due(current) - time.perf_counter()
        # Event.wait both paces the frames and wakes at once when asked to stop.
        if delay > 0 and stop.wait(delay):
            break
        if stop.is_set():
            break
        if upcoming is None or due(upcoming) > time.perf_counter():
            view.set_poses(bodies, current[1])
            shown += 1
        current = upcoming
    return shown
