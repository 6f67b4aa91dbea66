"""A robot execution recorded as a .viser file that viser's own browser client plays back (`?playbackPath=`),
so watching the robot costs the server one file per execution instead of 30 pushed messages a second.

One SceneView per process (the "studio", no browser ever connects to it) re-poses the scene for each
recording under a lock; viser's scene serializer (ViserServer.get_scene_serializer) snapshots the scene,
then records every pose change with the sleeps between frames.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from pathlib import Path

import mujoco

from .recording import Recording
from ..recording_store import VISER_SUFFIX, FileRecordingStore, RecordingId
from .view import SceneView

SUFFIX = VISER_SUFFIX
# viser's player starts a recording again once it reaches its end; holding the last pose this long keeps a
# finished execution still on screen (the participant judges it) instead of replaying it by itself.
HOLD_SECONDS = 600.0


def viser_path(data_dir: Path | str, rid: RecordingId) -> Path:
    """Where the .viser file of a recorded step is kept (next to its .npz and .json)."""
    return FileRecordingStore(data_dir).playable(rid)


class Studio:
    """Turns recordings into .viser files with one hidden viser server; thread-safe (one recording at a time)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self._model = model
        self._view: SceneView | None = None
        self._lock = threading.Lock()

    def render(self, recording: Recording, captions: Sequence[tuple[float, str]] = (), *, speed: float = 1.0) -> bytes:
        """The .viser bytes of a recording played at `speed`; captions are (recording time, text) to show from then."""
        if speed <= 0:
            raise ValueError(f"speed {speed} is not positive: expected a playback rate such as 1.0")
        if len(recording) == 0:
            raise ValueError("the recording has no frames: expected at least one pose")
        with self._lock:
            if self._view is None:
                self._view = SceneView(self._model, clickable=())
            view = self._view
            view.set_caption("")
            view.set_poses(recording.bodies, recording.poses[0])
            serializer = view.server.get_scene_serializer()
            pending = sorted(captions)
            previous = float(recording.times[0])
            for t, poses in zip(recording.times, recording.poses, strict=True):
                serializer.insert_sleep(max(0.0, (float(t) - previous) / speed))
                previous = float(t)
                while pending and pending[0][0] <= t:
                    view.set_caption(pending.pop(0)[1])
                view.set_poses(recording.bodies, poses)
            view.set_caption("")
            serializer.insert_sleep(HOLD_SECONDS)
            return serializer.serialize()

    def close(self) -> None:
        """Stop the hidden viser server."""
        with self._lock:
            if self._view is not None:
                self._view.close()
                self._view = None


def write_atomically(path: Path, data: bytes) -> None:
    """Write a file so that a reader in another process sees either nothing or all of it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)
