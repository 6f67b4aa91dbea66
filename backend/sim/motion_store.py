"""Executions worked out once and shared: the same scene, start seed, objects and playback rate give the same
motion (physics is deterministic), so an execution's recording and .viser file are kept under a digest of
those inputs (and of the code and library versions that make the motion) and every participant whose
execution is the same gets hard links to them in their own folder, with a .json of their own.

<data_dir>/recordings/motion/<digest>.npz, .viser and .json (the plan); tableteach.recording_store removes a
shared motion once no participant's file links it (erasure).
"""

from __future__ import annotations

import json
import os
import shutil
import threading
from collections.abc import Sequence
from pathlib import Path

from ..recording_store import VISER_SUFFIX, FileRecordingStore, RecordingId
from ..robot import ExecutionPlan
from .digests import digest_of, scene_digest
from .recordings import SavedRecording, recording_paths, save_meta


def motion_digest(scene: Path | str, seed: int, events: Sequence[str], rate: float, captions: Sequence[str]) -> str:
    """The name of an execution's shared motion: a digest of everything that decides it."""
    return digest_of({"scene": scene_digest(scene), "seed": int(seed), "events": list(events), "rate": float(rate),
                      "captions": list(captions)})


def _temporary(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")


def _link_as(source: Path, target: Path) -> None:
    """Make `target` another name of `source` (a copy where the file system has no hard links), replacing it."""
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary(target)
    try:
        os.link(source, tmp)
    except FileNotFoundError:
        raise  # the source is gone (a sweep took it): the caller works the motion out again
    except OSError:
        shutil.copyfile(source, tmp)
    os.replace(tmp, target)


class MotionStore:
    """The shared motions of one data folder."""

    def __init__(self, data_dir: Path | str) -> None:
        self.data_dir = Path(data_dir)
        self.folder = FileRecordingStore(data_dir).shared_folder

    def _shared(self, digest: str, suffix: str) -> Path:
        return self.folder / f"{digest}{suffix}"

    def give(self, digest: str, rid: RecordingId) -> ExecutionPlan | None:
        """Give the step `rid` the shared motion `digest` (its files linked, its own .json) and return the plan;
        None if there is no such motion (or it was removed meanwhile)."""
        try:
            plan = json.loads(self._shared(digest, ".json").read_text())
            npz, _meta = recording_paths(self.data_dir, rid)
            _link_as(self._shared(digest, ".npz"), npz)
            _link_as(self._shared(digest, VISER_SUFFIX), FileRecordingStore(self.data_dir).playable(rid))
        except FileNotFoundError:
            return None
        trace = tuple(frozenset(labels) for labels in plan["trace"])
        save_meta(self.data_dir, rid, tuple(plan["events"]), trace, tuple(plan["action_ends"]), plan["duration"])
        return ExecutionPlan(tuple(plan["events"]), trace, tuple(plan["plan_ends"]), viewable=True)

    def keep(self, digest: str, saved: SavedRecording, playable: bytes, plan: ExecutionPlan) -> None:
        """Save a worked-out execution as the shared motion `digest` and as the step saved.id's recording."""
        npz, _meta = recording_paths(self.data_dir, saved.id)
        viser_file = FileRecordingStore(self.data_dir).playable(saved.id)
        self.folder.mkdir(parents=True, exist_ok=True)
        npz.parent.mkdir(parents=True, exist_ok=True)
        for suffix, own, data in ((".npz", npz, None), (VISER_SUFFIX, viser_file, playable)):
            tmp = _temporary(self._shared(digest, suffix))
            if data is None:
                saved.recording.save(tmp)
            else:
                tmp.write_bytes(data)
            _link_as(tmp, own)  # the participant's link first: a sweep never sees the shared file unlinked
            os.replace(tmp, self._shared(digest, suffix))
        save_meta(self.data_dir, saved.id, saved.events, saved.trace, saved.action_ends, saved.recording.duration)
        shared_plan = _temporary(self._shared(digest, ".json"))
        shared_plan.write_text(json.dumps({
            "events": list(saved.events), "trace": [sorted(labels) for labels in saved.trace],
            "action_ends": list(saved.action_ends), "duration": saved.recording.duration,
            "plan_ends": list(plan.action_ends),
        }))
        os.replace(shared_plan, self._shared(digest, ".json"))  # last: a motion with a plan is complete

