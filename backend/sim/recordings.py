"""Where the study server keeps the robot's recorded motions: one .npz (poses) plus one .json (what
happened) per step, under <data_dir>/recordings/participant-<uid>/task-<i>/<kind>-<j>.*; numpy only.

<uid> is the participant's random 128-bit uid (participants.uid), not their number: a new database or a
second server on the same folder can never show one person's motion as another's. delete_recordings
removes all of a participant's files (for erasure)."""

from __future__ import annotations

import json
import os
import threading
from dataclasses import dataclass
from pathlib import Path

from .recording import Recording

from ..recording_store import FOLDER, STEP_KINDS, FileRecordingStore, RecordingId, check_uid

__all__ = ["FOLDER", "STEP_KINDS", "RecordingId", "SavedRecording", "check_uid", "delete_recordings",
           "list_recordings", "load_recording", "save_meta", "save_recording"]


@dataclass(frozen=True)
class SavedRecording:
    """A recorded step: body poses over time, the objects the robot moved and the labels it reported."""

    id: RecordingId
    recording: Recording
    events: tuple[str, ...]  # objects in the order the robot placed them
    trace: tuple[frozenset[str], ...]  # labels initially and after each action
    action_ends: tuple[float, ...]  # recording time (s) at which each action ended


def recording_paths(data_dir: Path | str, rid: RecordingId) -> tuple[Path, Path]:
    """The step's .npz and .json paths."""
    base = Path(data_dir) / FOLDER / rid.name
    return base.with_suffix(".npz"), base.with_suffix(".json")


def save_recording(data_dir: Path | str, saved: SavedRecording) -> Path:
    """Write the step's .npz and .json (replacing an earlier save of the same step); the .npz path.

    The .npz is written aside and renamed over the old one, never through it: that may be a link to motion other
    participants share (tableteach.sim.motion_store)."""
    npz, _meta = recording_paths(data_dir, saved.id)
    npz.parent.mkdir(parents=True, exist_ok=True)
    tmp = npz.with_name(f".{npz.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    saved.recording.save(tmp)
    os.replace(tmp, npz)
    save_meta(data_dir, saved.id, saved.events, saved.trace, saved.action_ends, saved.recording.duration)
    return npz


def save_meta(data_dir: Path | str, rid: RecordingId, events: tuple[str, ...], trace: tuple[frozenset[str], ...],
              action_ends: tuple[float, ...], duration: float) -> Path:
    """Write the step's .json (what happened), the participant's own file; its path."""
    _npz, meta = recording_paths(data_dir, rid)
    meta.parent.mkdir(parents=True, exist_ok=True)
    tmp = meta.with_name(f".{meta.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_text(json.dumps({
        "participant_uid": rid.participant_uid, "task_index": rid.task_index,
        "step_kind": rid.step_kind, "step_index": rid.step_index,
        "events": list(events), "trace": [sorted(labels) for labels in trace],
        "action_ends": list(action_ends), "duration": duration,
    }, indent=1))
    os.replace(tmp, meta)
    return meta


def list_recordings(data_dir: Path | str, participant_uid: str | None = None) -> list[RecordingId]:
    """Every saved step (of one participant if given), sorted by participant, task, kind and index."""
    root = Path(data_dir) / FOLDER
    pattern = (f"participant-{check_uid(participant_uid)}/task-*/*.npz" if participant_uid is not None
               else "participant-*/task-*/*.npz")
    out = []
    for path in root.glob(pattern):
        try:
            out.append(RecordingId.parse(path.relative_to(root).with_suffix("").as_posix()))
        except ValueError:
            continue  # a stray file someone put there
    return sorted(out, key=lambda r: (r.participant_uid, r.task_index, STEP_KINDS.index(r.step_kind), r.step_index))


def load_recording(data_dir: Path | str, rid: RecordingId) -> SavedRecording:
    """Read a saved step; FileNotFoundError naming the path if it was never saved."""
    npz, meta = recording_paths(data_dir, rid)
    if not npz.exists() or not meta.exists():
        raise FileNotFoundError(f"no recording of {rid.name} under {Path(data_dir) / FOLDER}: "
                                f"expected {npz} and {meta}")
    info = json.loads(meta.read_text())
    return SavedRecording(
        rid, Recording.load(npz), tuple(info["events"]), tuple(frozenset(x) for x in info["trace"]),
        tuple(float(t) for t in info["action_ends"]),
    )


def delete_recordings(data_dir: Path | str, participant_uid: str) -> int:
    """Remove every recording of one participant (their whole folder); the number of files removed."""
    return FileRecordingStore(data_dir).delete_participant(participant_uid)
