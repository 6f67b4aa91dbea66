"""Placements from clips: a world put at a placement's end from a clip is, bit for bit, the world that simulated
it, and a placement simulated on from a restored state is the one a fresh simulation makes."""

from __future__ import annotations

import numpy as np
import pytest

from tableteach.sim.clips import ClipCache
from tableteach.sim.physics import MujocoWorld
from tableteach.sim.world import PlacementError

ORDER = ("bowl", "dinner_plate", "knife")


def _assert_same_world(ours: MujocoWorld, fresh: MujocoWorld) -> None:
    for field in ("time", "qpos", "qvel", "qacc_warmstart", "ctrl", "eq_active", "xpos", "xquat", "xmat",
                  "geom_xpos", "geom_xmat", "qacc"):
        np.testing.assert_array_equal(getattr(ours.data, field), getattr(fresh.data, field), err_msg=field)
    np.testing.assert_array_equal(ours.model.eq_data, fresh.model.eq_data)
    assert ours.trace == fresh.trace and ours.placed == fresh.placed and ours.labels() == fresh.labels()
    np.testing.assert_array_equal(ours.recording.times, fresh.recording.times)
    np.testing.assert_array_equal(ours.recording.poses, fresh.recording.poses)


def test_placements_from_clips_and_continued_from_them_equal_a_fresh_simulation() -> None:
    fresh = MujocoWorld(11)
    for obj in ORDER:
        fresh.place(obj)
    cache = ClipCache()
    first = MujocoWorld(11)
    for obj in ORDER[:2]:
        cache.place(first, obj)
    assert (cache.hits, cache.misses, len(cache)) == (0, 2, 2)

    again = MujocoWorld(11)
    for obj in ORDER[:2]:
        cache.place(again, obj)  # no physics: both from clips
    assert (cache.hits, cache.misses) == (2, 2)
    cache.place(again, ORDER[2])  # simulated on from the restored state
    assert cache.misses == 3
    _assert_same_world(again, fresh)

    replayed = MujocoWorld(11)
    for obj in ORDER:
        cache.place(replayed, obj)
    assert cache.hits == 5
    _assert_same_world(replayed, fresh)
    # and the next placement, simulated on after clips only, is the fresh one's too
    fresh.place("fork")
    cache.place(replayed, "fork")
    _assert_same_world(replayed, fresh)


def test_clips_are_kept_apart_by_seed_and_history_and_refusals_change_nothing() -> None:
    cache = ClipCache()
    cache.place(MujocoWorld(1), "bowl")
    other_seed, other_history = MujocoWorld(2), MujocoWorld(1)
    cache.place(other_seed, "bowl")
    other_history.place("knife")  # not through the cache: the history still says what happened
    cache.place(other_history, "bowl")
    assert (cache.hits, cache.misses) == (0, 3)
    with pytest.raises(PlacementError, match="already moved"):
        cache.place(other_history, "bowl")
    assert other_history.placed == ("knife", "bowl")


def test_the_cache_keeps_within_its_memory_budget_dropping_the_least_recently_used() -> None:
    probe = ClipCache()
    probe.place(MujocoWorld(0), "fork")
    budget = int(probe.nbytes * 2.5)
    cache = ClipCache(max_bytes=budget)
    for seed in range(4):
        cache.place(MujocoWorld(seed), "fork")
        assert cache.nbytes <= budget
    assert len(cache) == 2
    cache.place(MujocoWorld(3), "fork")
    assert cache.hits == 1  # the newest was kept
    cache.place(MujocoWorld(0), "fork")
    assert cache.hits == 1  # the oldest was dropped



def test_clips_written_by_one_process_serve_another_on_the_same_data_folder(tmp_path) -> None:
    from tableteach.sim.clips import clip_folder

    folder = clip_folder(tmp_path)
    server, worker = ClipCache(folder=folder), ClipCache(folder=folder)  # as two processes: memory apart
    first = MujocoWorld(5)
    for obj in ORDER[:2]:
        server.place(first, obj)
    assert len(list(folder.glob("*.npz"))) == 2
    fresh = MujocoWorld(5)
    for obj in ORDER:
        fresh.place(obj)
    theirs = MujocoWorld(5)
    for obj in ORDER:
        worker.place(theirs, obj)
    assert (worker.hits, worker.misses) == (2, 1)  # the first two read from the server's files
    _assert_same_world(theirs, fresh)

    for path in folder.glob("*.npz"):
        path.write_bytes(b"not a clip")
    again = ClipCache(folder=folder)
    again.place(MujocoWorld(5), ORDER[0])
    assert (again.hits, again.misses) == (0, 1)  # an unreadable file is simulated again, never trusted


def test_warming_simulates_every_order_once_and_then_every_placement_comes_from_its_file(tmp_path) -> None:
    from tableteach.sim.clips import clip_folder, warm

    folder = clip_folder(tmp_path)
    assert warm(ClipCache(folder=folder), 8, objects=("bowl", "fork")) == (4, 0)  # bowl, bowl-fork, fork, fork-bowl
    assert warm(ClipCache(folder=folder), 8, objects=("bowl", "fork")) == (0, 4)
    later = ClipCache(folder=folder)
    for order in (("fork", "bowl"), ("bowl", "fork")):
        world = MujocoWorld(8)
        for obj in order:
            later.place(world, obj)
    assert (later.hits, later.misses) == (4, 0)
