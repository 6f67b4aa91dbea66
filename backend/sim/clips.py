"""Placements simulated once: the same placement after the same earlier ones on the same table (scene and
seed) is the same motion every time, physics being deterministic, so a ClipCache keeps each as a Clip (its
frames, labels and end state) and puts the next world that asks at its end without simulating it. A placement
not seen yet is simulated on from the restored state and kept. Labels still come from MuJoCo's state, as it
was when the clip was simulated.

Clips are kept in memory (least recently used dropped first past a budget) and, given a folder, as files
(<data_dir>/robot-cache/clips/<digest>.npz, no pickle) that every process on the data folder reads, the
server's and its robot workers', across restarts. The files hold no participant's data (a clip is physics
for a table and a sequence of objects, named by a digest of them) and can be deleted at any time; the tree of
one task's placements (at most 325 orders of prefixes of five objects) is about 45 MB."""

from __future__ import annotations

import os
import threading
import zipfile
from collections import OrderedDict
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .digests import digest_of, scene_digest
from .physics import Clip, MujocoWorld
from .scene import SCENE_XML

CLIP_CACHE_BYTES = 64 * 2**20  # a clip of a 5.5 s placement holds about 0.14 MB
CACHE_FOLDER = "robot-cache"  # under the data folder, next to recordings/: the robot's caches, not anyone's data
Key = tuple[str, int, tuple[tuple[str, bool], ...], str]  # scene, seed, actions so far, object


def clip_folder(data_dir: Path | str) -> Path:
    """Where the clips of a data folder are kept."""
    return Path(data_dir) / CACHE_FOLDER / "clips"


class ClipCache:
    """Clips keyed by (scene, seed, the actions before, object); thread-safe (each world used by one thread)."""

    def __init__(self, max_bytes: int = CLIP_CACHE_BYTES, folder: Path | str | None = None) -> None:
        if max_bytes < 0:
            raise ValueError(f"max_bytes {max_bytes} is negative: expected a memory budget in bytes, 0 to keep none")
        self.max_bytes = max_bytes
        self.folder = None if folder is None else Path(folder)
        self._clips: OrderedDict[Key, Clip] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = 0  # placements from a clip (in memory or read from its file)
        self.misses = 0  # placements simulated

    def place(self, world: MujocoWorld, obj: str) -> frozenset[str]:
        """Place `obj` on the world, from a clip if one fits its history, else simulated (and kept); the labels."""
        history = world.history
        if history is None:  # an action under way: the state is not what the history says
            return world.place(obj)
        key: Key = (*history, obj)
        with self._lock:
            clip = self._clips.get(key)
            if clip is not None:
                self._clips.move_to_end(key)
        if clip is None:
            clip = self._read(key)
            if clip is not None:
                self._keep(key, clip)
        if clip is not None:
            labels = world.replay(clip)
            with self._lock:
                self.hits += 1
            return labels
        clip = world.place_clip(obj)  # PlacementError before anything moves
        with self._lock:
            self.misses += 1
        self._keep(key, clip)
        self._write(key, clip)
        return clip.labels

    def _keep(self, key: Key, clip: Clip) -> None:
        with self._lock:
            if key in self._clips or clip.nbytes > self.max_bytes:
                return
            self._clips[key] = clip
            self._bytes += clip.nbytes
            while self._bytes > self.max_bytes:
                _key, old = self._clips.popitem(last=False)
                self._bytes -= old.nbytes

    def _path(self, key: Key) -> Path | None:
        if self.folder is None:
            return None
        scene, seed, done, obj = key
        name = digest_of({"clip": [scene_digest(scene), seed, [list(action) for action in done], obj]})
        return self.folder / f"{name}.npz"

    def _read(self, key: Key) -> Clip | None:
        path = self._path(key)
        if path is None:
            return None
        try:
            with np.load(path, allow_pickle=False) as npz:
                return Clip(str(npz["obj"]), npz["times"], npz["poses"], frozenset(str(x) for x in npz["labels"]),
                            npz["before_last_tick"], npz["eq_data"], float(npz["next_frame"]))
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
            return None  # not made yet, or unreadable: simulated (and written) again

    def _write(self, key: Key, clip: Clip) -> None:
        path = self._path(key)
        if path is None:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        with tmp.open("wb") as f:
            np.savez(f, obj=np.array(clip.obj), times=clip.times, poses=clip.poses,
                     labels=np.array(sorted(clip.labels), dtype=str), before_last_tick=clip.before_last_tick,
                     eq_data=clip.eq_data, next_frame=np.array(clip.next_frame))
        os.replace(tmp, path)

    @property
    def nbytes(self) -> int:
        """Memory the kept clips hold."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._clips)

    def clear(self) -> None:
        """Drop every clip held in memory (their files stay)."""
        with self._lock:
            self._clips.clear()
            self._bytes = 0


def _orders(objects: tuple[str, ...], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Every non-empty sequence of distinct objects, each after its own prefix (depth first)."""
    for obj in objects:
        if obj not in prefix:
            yield (*prefix, obj)
            yield from _orders(objects, (*prefix, obj))


def warm(cache: ClipCache, seed: int, scene: Path = SCENE_XML,
         objects: tuple[str, ...] | None = None) -> tuple[int, int]:
    """Make the cache hold every placement any participant or execution can ask for on a table started from
    `seed` (each object after every sequence of the others, of all objects unless given: the whole tree, 325
    placements for five objects); (placements simulated now, placements the cache had)."""
    before = cache.misses
    world = MujocoWorld(seed, scene)
    objects = world.objects if objects is None else objects
    try:
        for sequence in _orders(objects):
            if world.placed != sequence[:-1]:
                world.reset(seed)
                for obj in sequence[:-1]:
                    cache.place(world, obj)  # from the clips made moments ago
            cache.place(world, sequence[-1])
    finally:
        world.close()
    # the replays that rebuilt each prefix are hits too: count only the tree's nodes
    misses = cache.misses - before
    nodes = sum(1 for _ in _orders(objects))
    return misses, nodes - misses
