"""Recordings round-trip through .npz files that load without pickle."""

import numpy as np
import pytest

from tableteach.sim.recording import Recording


def _recording(frames: int = 5) -> Recording:
    rng = np.random.default_rng(0)
    return Recording(("hand", "bowl"), np.arange(frames) / 30.0, rng.normal(size=(frames, 2, 7)))


def test_save_and_load_round_trip_without_pickle(tmp_path):
    original = _recording()
    path = original.save(tmp_path / "run.npz")
    with np.load(path, allow_pickle=False) as raw:  # plain arrays only
        assert raw["bodies"].dtype.kind == "U"
    loaded = Recording.load(path)
    assert loaded.bodies == original.bodies
    np.testing.assert_array_equal(loaded.times, original.times)
    np.testing.assert_array_equal(loaded.poses, original.poses)


def test_since_and_duration():
    rec = _recording(10)
    assert len(rec.since(4)) == 6
    assert rec.duration == pytest.approx(9 / 30)


def test_rejects_inconsistent_shapes_and_foreign_files(tmp_path):
    with pytest.raises(ValueError, match=r"expected \(3, 2, 7\)"):
        Recording(("a", "b"), np.zeros(3), np.zeros((3, 1, 7)))
    np.savez(tmp_path / "other.npz", x=np.zeros(2))
    with pytest.raises(ValueError, match="lacks arrays"):
        Recording.load(tmp_path / "other.npz")
