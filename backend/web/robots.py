"""The composition root's adapters from tableteach.sim (the only module outside it that imports it): the robot (the
trace robot, or the MuJoCo one, imported only when the settings name it), the recording store and viser's page."""

from __future__ import annotations

from ..config import Settings
from ..db.engine import Database
from ..db.shared_recordings import make_store
from ..recording_store import RecordingStore
from ..robot import Robot, TraceRobot


def make_robot(settings: Settings) -> Robot:
    """The robot implementation Settings.robot names (mujoco and viser are imported only for 'mujoco')."""
    if settings.robot == "trace":
        return TraceRobot("dinner", settings.robot_seconds_per_object)
    if settings.robot == "mujoco":
        from ..sim.robot import MujocoRobot  # imports mujoco and viser

        return MujocoRobot(speed=settings.robot_speed, data_dir=settings.data_dir, workers=settings.robot_workers)
    raise ValueError(f"unknown robot {settings.robot!r}; expected 'trace' or 'mujoco'")


def warm_robot(settings: Settings, tasks: int) -> dict[str, int]:
    """Have the MuJoCo robot simulate every placement of the first `tasks` tasks' tables ahead (clip files under
    the data folder, shared by every process); how many it simulated and how many were kept already."""
    from ..sim.robot import warm_tables  # imports mujoco

    return warm_tables(settings.data_dir, range(tasks))


def make_recording_store(settings: Settings, db: Database) -> RecordingStore:
    """The recording store the services use: files under the data folder, with the scene's top view; with
    TABLETEACH_RECORDING_STORE=database, kept in the database and that folder a cache of them."""
    from ..sim.top_view import scene_store  # MuJoCo is imported only when a replay asks for the layout

    return make_store(settings.recording_store, scene_store(settings.data_dir), db, settings.data_dir)


def viewer_client_html() -> bytes:
    """viser's built client page (the participant's 3D view and recorded-motion player)."""
    from ..sim.viewer_client import client_html

    return client_html()
