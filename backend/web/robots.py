"""Where the app gets its robot: the trace robot, or the MuJoCo one (imported only when the settings name it)."""

from __future__ import annotations

from ..config import Settings
from ..robot import Robot, TraceRobot


def make_robot(settings: Settings) -> Robot:
    """The robot implementation Settings.robot names (mujoco and viser are imported only for 'mujoco')."""
    if settings.robot == "trace":
        return TraceRobot("dinner", settings.robot_seconds_per_object)
    if settings.robot == "mujoco":
        from ..sim.robot import MujocoRobot  # imports mujoco and viser

        return MujocoRobot(speed=settings.robot_speed, data_dir=settings.data_dir, workers=settings.robot_workers)
    raise ValueError(f"unknown robot {settings.robot!r}; expected 'trace' or 'mujoco'")
