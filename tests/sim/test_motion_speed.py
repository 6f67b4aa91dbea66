"""The study's robot_speed on the MuJoCo robot's recorded executions: the .viser file the browser plays and the
plan's action ends are both at that speed, while the saved recording keeps real time."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest
import zstandard

from tableteach.sim.motion_file import HOLD_SECONDS, viser_path
from tableteach.sim.recordings import RecordingId, load_recording
from tableteach.sim.robot import MujocoRobot

EVENTS = ["dinner_plate", "fork"]


def _playback_seconds(path: Path) -> float:
    """How long viser's player takes for a .viser file's motion (its duration without the held last pose)."""
    data = path.read_bytes()
    inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=int.from_bytes(data[:8], "little"))
    length = int.from_bytes(inner[:8], "little")
    return float(msgspec.msgpack.decode(inner[8:8 + length])["durationSeconds"]) - HOLD_SECONDS


def test_the_playback_file_and_the_plan_follow_the_study_speed_and_the_recording_keeps_real_time(tmp_path) -> None:
    robot = MujocoRobot(data_dir=tmp_path)
    try:
        normal_id, fast_id = RecordingId("1" * 32, 0, "query", 0), RecordingId("2" * 32, 0, "query", 0)
        normal = robot.plan_execution("1/0", EVENTS, normal_id.name)
        fast = robot.plan_execution("1/0", EVENTS, fast_id.name, speed=2.0)
        with pytest.raises(ValueError, match="speed"):
            robot.plan_execution("1/0", EVENTS, fast_id.name, speed=0)
    finally:
        robot.shutdown()
    assert fast.action_ends == pytest.approx([end / 2 for end in normal.action_ends])
    assert _playback_seconds(viser_path(tmp_path, normal_id)) == pytest.approx(normal.action_ends[-1], abs=0.05)
    assert _playback_seconds(viser_path(tmp_path, fast_id)) == pytest.approx(fast.action_ends[-1], abs=0.05)
    real = load_recording(tmp_path, fast_id)
    assert real.action_ends[-1] - float(real.recording.times[0]) == pytest.approx(normal.action_ends[-1], abs=0.05)
