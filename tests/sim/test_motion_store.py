"""Shared motion: every participant of a task starts from the same table, so an execution worked out for one is
given to the next (hard links to the same files, a .json of their own) instead of being simulated again; each
still has their own recordings, and erasing a participant removes theirs and any shared motion nobody else
holds."""

from __future__ import annotations

import json
import uuid

import pytest

from tableteach.recording_store import FileRecordingStore
from tableteach.sim.motion_file import viser_path
from tableteach.sim.recordings import (RecordingId, SavedRecording, list_recordings, load_recording,
                                       recording_paths, save_recording)
from tableteach.sim.robot import MujocoRobot, table_seed
from tableteach.sim.work_out import StudioSource, execution_digest, work_out_execution

EVENTS = ("small_plate", "knife")


def _rid(kind: str = "query", index: int = 0) -> RecordingId:
    return RecordingId(uuid.uuid4().hex, 0, kind, index)


def _same_file(a, b) -> bool:
    return a.stat().st_ino == b.stat().st_ino


def test_the_start_table_is_the_same_for_every_participant_of_a_task_and_differs_between_tasks() -> None:
    assert table_seed("5/0") == table_seed("917/0") == table_seed("0")
    assert table_seed("5/0") != table_seed("5/1")


def test_a_second_participant_with_the_same_execution_gets_the_first_ones_motion_without_simulating(tmp_path):
    studio = StudioSource()
    first, second, third = _rid(), _rid("test", 1), _rid()
    try:
        plan = work_out_execution(studio, tmp_path, 7, EVENTS, first, 1.5)
        again = work_out_execution(studio, tmp_path, 7, EVENTS, second, 1.5)
        work_out_execution(studio, tmp_path, 7, EVENTS, third, 1.0)  # another rate: another file
    finally:
        studio.close()
    assert again == plan
    assert _same_file(viser_path(tmp_path, first), viser_path(tmp_path, second))
    assert _same_file(recording_paths(tmp_path, first)[0], recording_paths(tmp_path, second)[0])
    assert not _same_file(viser_path(tmp_path, first), viser_path(tmp_path, third))
    for rid in (first, second):  # each their own .json, naming them
        meta = json.loads(recording_paths(tmp_path, rid)[1].read_text())
        assert (meta["participant_uid"], meta["step_kind"], meta["step_index"]) == (rid.participant_uid,
                                                                                     rid.step_kind, rid.step_index)
        saved = load_recording(tmp_path, rid)
        assert saved.events == EVENTS and saved.trace == plan.trace
    assert list_recordings(tmp_path, second.participant_uid) == [second]


def test_erasure_removes_a_participants_files_and_the_shared_motion_only_once_nobody_holds_it(tmp_path) -> None:
    studio = StudioSource()
    first, second, alone = _rid(), _rid(), _rid()
    try:
        for rid in (first, second):
            work_out_execution(studio, tmp_path, 3, EVENTS, rid, 1.0)
        work_out_execution(studio, tmp_path, 3, ("fork",), alone, 1.0)
    finally:
        studio.close()
    store = FileRecordingStore(tmp_path)
    shared = store.shared_folder
    assert len(list(shared.iterdir())) == 6  # two motions: .npz, .viser, .json each

    assert store.delete_participant(first.participant_uid) == 3  # their .npz, .json and .viser
    assert load_recording(tmp_path, second).events == EVENTS and viser_path(tmp_path, second).exists()
    assert store.delete_participant(alone.participant_uid) == 3 + 3  # theirs, and the motion only they held
    assert {p.name.split(".")[0] for p in shared.iterdir()} == {execution_digest(3, EVENTS, 1.0)}
    assert store.delete_participant(second.participant_uid) == 3 + 3
    assert list(shared.iterdir()) == []


def test_saving_a_step_over_a_shared_motion_replaces_the_participants_file_and_leaves_the_others(tmp_path) -> None:
    studio = StudioSource()
    first, second = _rid(), _rid()
    try:
        for rid in (first, second):
            work_out_execution(studio, tmp_path, 4, EVENTS, rid, 1.0)
    finally:
        studio.close()
    before = load_recording(tmp_path, first)
    shorter = SavedRecording(second, before.recording.since(len(before.recording) - 2), (), (frozenset(),), ())
    save_recording(tmp_path, shorter)
    assert len(load_recording(tmp_path, second).recording) == 2
    assert len(load_recording(tmp_path, first).recording) == len(before.recording)


@pytest.mark.parametrize("workers", [0, 1])
def test_the_robot_gives_another_participants_table_of_the_task_the_motion_worked_out_before(tmp_path, workers):
    robot = MujocoRobot(data_dir=tmp_path, workers=workers)
    first, second = _rid(), _rid()
    try:
        plan = robot.plan_execution("11/0", EVENTS, first.name, speed=1.25)
        again = robot.plan_execution("12/0", EVENTS, second.name, speed=1.25)
        with pytest.raises(ValueError, match="teapot"):
            robot.plan_execution("13/0", ("teapot",), _rid().name)
    finally:
        robot.shutdown()
    assert again == plan
    assert _same_file(viser_path(tmp_path, first), viser_path(tmp_path, second))


def test_backups_leave_out_the_shared_motion_and_the_robots_caches_but_keep_each_participants_files(tmp_path):
    from tableteach.db.backup import _data_files

    studio = StudioSource()
    rid = _rid()
    try:
        work_out_execution(studio, tmp_path, 2, EVENTS, rid, 1.0)
    finally:
        studio.close()
    (tmp_path / "robot-cache" / "clips").mkdir(parents=True)
    (tmp_path / "robot-cache" / "clips" / "x.npz").write_bytes(b"clip")
    kept = {p.relative_to(tmp_path).as_posix() for p in _data_files(tmp_path)}
    assert kept == {f"recordings/{rid.name}{suffix}" for suffix in (".npz", ".json", ".viser")}
