"""One participant's simulation plus optional browser view, running executions in a worker thread.

Threading rules: run() returns at once and a single worker thread moves the robot; only one
execution at a time (run() while busy raises). The worker simulates frame by frame under a lock and,
if someone watches, paces the frames at wall-clock speed; otherwise it fast-forwards. Clicks arrive
on viser's threads. See docs/sim.md.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator, Sequence

import numpy as np

from .physics import MujocoWorld
from .playback import play_frames
from .recording import Recording
from .view import SceneView
from .world import check_sequence


class SessionBusyError(RuntimeError):
    """The robot is still executing; wait() for it first."""


class SceneSession:
    """A MujocoWorld and (optionally) a SceneView for one participant session."""

    def __init__(
        self,
        seed: int = 0,
        *,
        view: bool = True,
        on_click: Callable[[str], None] | None = None,
        realtime: bool | None = None,
        speed: float = 1.0,
    ) -> None:
        """`realtime`: replay motions at wall-clock speed always (True), never (False), or only while
        a browser is connected (None); `speed` > 1 replays faster than real time."""
        self.world = MujocoWorld(seed)
        self.view = SceneView(self.world.model, on_click=on_click) if view else None
        self.realtime = realtime
        self.speed = speed
        self._lock = threading.Lock()  # guards the world between the worker and readers
        self._stop = threading.Event()
        self._worker: threading.Thread | None = None
        self._error: BaseException | None = None
        self._trace = self.world.trace

    @property
    def busy(self) -> bool:
        """Whether an execution is still running (being simulated or shown)."""
        return self._worker is not None and self._worker.is_alive()

    @property
    def trace(self) -> list[frozenset[str]]:
        """Labels of the initial state and after every action shown so far."""
        with self._lock:
            return list(self._trace)

    @property
    def placed(self) -> tuple[str, ...]:
        """Objects the robot has taken off Table A (in order), including one being moved now."""
        with self._lock:
            return self.world.placed

    def labels(self) -> frozenset[str]:
        """Propositions true in the simulated state (may run ahead of what the view shows)."""
        with self._lock:
            return self.world.labels()

    @property
    def recording(self) -> Recording:
        """Body poses since the last reset, for saving or replaying."""
        with self._lock:
            return self.world.recording

    def run(self, objects: Sequence[str], *, drop: Iterable[str] = ()) -> None:
        """Start placing `objects` in order in the worker thread (dropping those in `drop`)."""
        if self.busy:
            raise SessionBusyError("the robot is still executing: expected wait() before the next run()")
        objects, drop = list(objects), set(drop)
        with self._lock:
            moved = tuple(self.world.placed)
        check_sequence(objects, self.world.objects, moved)  # refuse the whole request before anything moves
        self._error = None
        self._stop.clear()
        self._worker = threading.Thread(target=self._execute, args=(objects, drop), name="scene-session", daemon=True)
        self._worker.start()

    def wait(self, timeout: float | None = None) -> list[frozenset[str]]:
        """Block until the execution ends; return the trace, or re-raise the worker's error."""
        if self._worker is not None:
            self._worker.join(timeout)
            if self._worker.is_alive():
                raise TimeoutError(f"execution still running after {timeout} s: expected a longer timeout")
        if self._error is not None:
            raise self._error
        return self.trace

    def reset(self, seed: int = 0) -> None:
        """Put everything back on Table A; refused while busy."""
        if self.busy:
            raise SessionBusyError("cannot reset while the robot is executing: expected wait() first")
        with self._lock:
            self.world.reset(seed)
            self._trace = self.world.trace
            snapshot = self.world.recording.since(len(self.world.recording) - 1)
        if self.view is not None:
            self.view.set_poses(snapshot.bodies, snapshot.poses[0])
            for obj in self.world.objects:
                self.view.set_clickable(obj, True)
            self.view.set_caption("")

    def close(self) -> None:
        """Stop any execution, stop the view's server (threads and port released) and the world."""
        self._stop.set()
        if self._worker is not None:
            self._worker.join(timeout=10.0)
        if self.view is not None:
            self.view.close()
        self.world.close()

    def _locked(self, frames: Iterator[tuple[float, np.ndarray]]) -> Iterator[tuple[float, np.ndarray]]:
        """Advance the simulation only while holding the lock, so readers see whole control ticks."""
        while True:
            with self._lock:
                frame = next(frames, None)
            if frame is None:
                return
            yield frame

    def _watching(self) -> bool:
        if self.view is None or self.realtime is False:
            return False
        return self.realtime is True or self.view.client_count > 0

    def _execute(self, objects: list[str], drop: set[str]) -> None:
        try:
            for obj in objects:
                if self._stop.is_set():
                    return
                if self.view is not None:
                    self.view.set_clickable(obj, False)
                    self.view.set_caption(f"The robot is placing the {obj.replace('_', ' ')}")
                with self._lock:
                    frames = self._locked(self.world.place_frames(obj, drop=obj in drop))
                if self.view is not None and self._watching():
                    # Simulate while replaying: motion starts after one frame's worth of physics.
                    play_frames(self.world.bodies, frames, self.view, speed=self.speed, stop=self._stop)
                for _ in frames:  # finish the action in fast-forward if nobody watched or we were stopped
                    pass
                with self._lock:
                    self._trace.append(self.world.trace[-1])
                    final = self.world.body_poses()
                if self.view is not None:
                    self.view.set_poses(self.world.bodies, final)
        except BaseException as error:  # handed to wait()
            self._error = error
        finally:
            if self.view is not None:
                self.view.set_caption("")
