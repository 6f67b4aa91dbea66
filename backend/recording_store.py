"""The recording store seam: where the robot's recorded motions are kept, named by participant uid and step.

The services name recordings with RecordingId and reach the files through RecordingStore only; the files
themselves are written by the robot (tableteach.sim). FileRecordingStore keeps them under
<data_dir>/recordings/participant-<uid>/task-<i>/<kind>-<j>.{npz,json,viser}.

A robot may share motion between participants (the same table and plan give the same motion): the shared
files live under <data_dir>/recordings/motion/<digest>.* and each participant's .npz and .viser are hard links
to them (their .json is their own). Erasing a participant removes their folder and then every shared motion
that no participant's file links any more.

Where several hosts serve one study (TABLETEACH_RECORDING_STORE=database), tableteach.db.shared_recordings keeps
the finished files in the database as well and uses this folder as each host's cache of them.
"""

from __future__ import annotations

import hashlib
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from .scenes.spec import SceneSpec

FOLDER = "recordings"
SHARED_FOLDER = "motion"  # under FOLDER: motion files shared by participants (hard-linked into their folders)
VISER_SUFFIX = ".viser"
STEP_KINDS = ("practice", "demonstration", "query", "test")
SUFFIXES = (".npz", ".json", VISER_SUFFIX)  # a step's files: poses, what happened, the browser's motion file
_UID = re.compile(r"^[0-9a-f]{32}$")
_NAME = re.compile(r"^participant-([0-9a-f]{32})/task-(\d+)/(practice|demonstration|query|test)-(\d+)$")


def check_uid(uid: str) -> str:
    """The uid itself if it is 32 lowercase hex digits (so it is safe as a folder name), else ValueError."""
    if not isinstance(uid, str) or not _UID.match(uid):
        raise ValueError(f"participant uid {uid!r}: expected 32 lowercase hex digits")
    return uid


@dataclass(frozen=True, order=True)
class RecordingId:
    """Which step of which participant a recording shows (indices count from 0, as in the API)."""

    participant_uid: str
    task_index: int
    step_kind: str
    step_index: int

    def __post_init__(self) -> None:
        check_uid(self.participant_uid)
        if self.step_kind not in STEP_KINDS:
            raise ValueError(f"step_kind is {self.step_kind!r}: expected one of {', '.join(STEP_KINDS)}")
        if min(self.task_index, self.step_index) < 0:
            raise ValueError(f"{self} has a negative index: expected whole numbers >= 0")

    @property
    def name(self) -> str:
        """The relative path without suffix, e.g. participant-<uid>/task-0/query-1."""
        return f"participant-{self.participant_uid}/task-{self.task_index}/{self.step_kind}-{self.step_index}"

    @classmethod
    def parse(cls, name: str) -> RecordingId:
        """The id a name() string stands for."""
        match = _NAME.match(name)
        if match is None:
            raise ValueError(f"recording name {name!r}: expected participant-<uid>/task-<i>/<kind>-<j> "
                             "with a 32-hex-digit uid")
        uid, task, kind, index = match.groups()
        return cls(uid, int(task), kind, int(index))


@dataclass(frozen=True)
class RecordingFile:
    """One finished recording file: its name under the recordings folder and its bytes."""

    name: str  # participant-<uid>/task-<i>/<kind>-<j>.<suffix>
    participant_uid: str
    data: bytes

    @property
    def digest(self) -> str:
        """The SHA-256 of the bytes (the name they are kept by)."""
        return hashlib.sha256(self.data).hexdigest()


class RecordingStore(Protocol):
    """What the services need of the recordings: the browser's file of a step, and erasure."""

    def playable(self, rid: RecordingId) -> Path:
        """Where the step's .viser file (for the browser) is or will be."""
        ...

    def ready(self, rid: RecordingId) -> bool:
        """Whether the step's .viser file is at playable(rid) now (fetched there from a shared store if need be)."""
        ...

    def finished(self, rid: RecordingId) -> list[RecordingFile]:
        """The step's finished files to keep where every host reaches them ([] for a store of local files)."""
        ...

    def delete_participant(self, participant_uid: str) -> int:
        """Remove every recording of one participant; the number of files removed."""
        ...

    def cached_uids(self) -> list[str]:
        """The participants of whom this host holds copies of files kept elsewhere ([] for a store of local files)."""
        ...

    def forget_cached(self, participant_uids: list[str]) -> int:
        """Remove this host's copies of these participants' files (erased on another host); how many folders."""
        ...

    def layout(self, scene: SceneSpec | None = None) -> dict[str, Any]:
        """The scene seen from above (tables, robot base, objects' footprints, starts and slots), for replays: the
        dinner table's, or that of a study's own objects."""
        ...

    def top_view(self, rid: RecordingId, scene: SceneSpec | None = None) -> dict[str, Any] | None:
        """A recorded step's poses from above, thinned for the dashboard, or None if none was saved."""
        ...


class FileRecordingStore:
    """Recordings as files under data_dir (one folder per participant), without the scene's geometry (the
    composition root gives the services tableteach.sim.top_view's store, which adds it)."""

    def __init__(self, data_dir: Path | str) -> None:
        self.data_dir = Path(data_dir)

    def playable(self, rid: RecordingId) -> Path:
        """The step's .viser file path."""
        return (self.data_dir / FOLDER / rid.name).with_suffix(VISER_SUFFIX)

    def ready(self, rid: RecordingId) -> bool:
        """Whether the step's .viser file exists."""
        return self.playable(rid).is_file()

    def finished(self, rid: RecordingId) -> list[RecordingFile]:
        """Nothing to keep elsewhere: the files are where they are kept."""
        return []

    def cached_uids(self) -> list[str]:
        """No copies: the files are where they are kept."""
        return []

    def forget_cached(self, participant_uids: list[str]) -> int:
        """No copies to remove (erasure removed the files themselves)."""
        return 0

    def delete_participant(self, participant_uid: str) -> int:
        """Remove the participant's folder, then the shared motion nobody links any more; the number of files."""
        folder = self.data_dir / FOLDER / f"participant-{check_uid(participant_uid)}"
        if not folder.exists():
            return 0
        removed = sum(1 for path in folder.rglob("*") if path.is_file())
        shutil.rmtree(folder)
        return removed + self.sweep_shared()

    @property
    def shared_folder(self) -> Path:
        """Where motion shared by participants is kept."""
        return self.data_dir / FOLDER / SHARED_FOLDER

    def sweep_shared(self) -> int:
        """Remove every shared motion (its files by one stem) of which no file has a link outside the shared
        folder; the number of files removed. A robot links a new motion into a participant's folder before
        it gives it its shared name, so a sweep never takes one being written."""
        folder = self.shared_folder
        if not folder.exists():
            return 0
        groups: dict[str, list[Path]] = {}
        for path in folder.iterdir():
            if not path.name.startswith("."):  # a file still being written
                groups.setdefault(path.name.split(".", 1)[0], []).append(path)
        removed = 0
        for paths in groups.values():
            try:
                if any(p.stat().st_nlink > 1 for p in paths):
                    continue
            except FileNotFoundError:
                continue  # another sweep got there first
            for path in paths:
                try:
                    path.unlink()
                    removed += 1
                except FileNotFoundError:
                    pass
        return removed

    def layout(self, scene: SceneSpec | None = None) -> dict[str, Any]:
        """No scene known here: ValueError (the app is composed with the scene's store)."""
        raise ValueError("this recording store knows no scene: expected the app's SceneRecordingStore")

    def top_view(self, rid: RecordingId, scene: SceneSpec | None = None) -> dict[str, Any] | None:
        """No scene known here, so no top view."""
        return None
