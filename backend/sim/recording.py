"""Body poses over time for replaying an execution; saved as .npz without pickle."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Recording:
    """Poses of the moving bodies: `poses[f, b]` is (x, y, z, qw, qx, qy, qz) of `bodies[b]` at `times[f]`."""

    bodies: tuple[str, ...]
    times: np.ndarray  # (F,) seconds of simulated time
    poses: np.ndarray  # (F, B, 7)

    def __post_init__(self) -> None:
        f, b = len(self.times), len(self.bodies)
        if self.poses.shape != (f, b, 7):
            raise ValueError(
                f"poses have shape {self.poses.shape}: expected ({f}, {b}, 7) for {f} times and {b} bodies"
            )

    def __len__(self) -> int:
        return len(self.times)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return float(self.times[-1] - self.times[0]) if len(self) else 0.0

    def since(self, frame: int) -> Recording:
        """The frames from index `frame` on."""
        return Recording(self.bodies, self.times[frame:], self.poses[frame:])

    def save(self, path: Path | str) -> Path:
        """Write an .npz file (plain arrays, loadable with allow_pickle=False).

        Not compressed: deflate shrinks the poses by a third only and cost 30 ms of CPU per recorded step."""
        path = Path(path)
        with path.open("wb") as f:
            np.savez(f, bodies=np.array(self.bodies, dtype=str), times=self.times, poses=self.poses)
        return path

    @classmethod
    def load(cls, path: Path | str) -> Recording:
        """Read a file written by save()."""
        with np.load(Path(path), allow_pickle=False) as npz:
            missing = {"bodies", "times", "poses"} - set(npz.files)
            if missing:
                raise ValueError(f"{path} lacks arrays {sorted(missing)}: expected a recording saved by Recording.save")
            return cls(tuple(str(b) for b in npz["bodies"]), npz["times"].astype(float), npz["poses"].astype(float))
