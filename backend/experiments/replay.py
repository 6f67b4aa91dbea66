"""Counterfactual replay of a study's export: each participant's recorded demonstrations and verdicts run
again through other learner configurations, step by step, next to what the study's robot learned.

A learner spec is ``study`` (the study's own prior and flip rate) or comma-separated settings
``prior=NAME``, ``flip=P`` (the noise-aware learner, P in [0, 0.5)) and ``data=demonstrations`` (the
demonstrations only, as Batch would learn from the same session); core.counterfactual says more. The
recorded queries stay what they were: a replay changes what is learned from the data, not which
executions were shown.
"""

from __future__ import annotations

import csv
import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

from ..core.belief import check_flip_rate
from ..core.counterfactual import DATA_CHOICES, LearnerSpec, parse_learners, step_views
from ..core.domain import get_domain, objects_task
from ..core.session import Trace, Verdicts

__all__ = ["DATA_CHOICES", "LearnerSpec", "parse_learners", "read_export", "replay", "sessions", "study_flip_rate"]

# The beliefs.csv columns a replay reads; an export without them was written by another version.
BELIEF_COLUMNS = ("participant_id", "condition", "task_index", "task", "step", "record_kind", "acceptable", "trace",
                  "entropy", "map_formula", "similarity")
STUDY_KEYS = ("prior", "tasks")
REPLAY_COLUMNS = ("participant_id", "condition", "task_index", "task", "step", "record_kind", "learner",
                  "similarity", "entropy", "map_formula", "study_similarity", "study_entropy", "study_map_formula")


@dataclass(frozen=True)
class Export:
    """What a replay needs from a study's export: the study definition and beliefs.csv."""

    study: dict[str, Any]
    beliefs: list[dict[str, str]]


def read_export(path: Path | str) -> Export:
    """Read exports.zip or a folder holding its files; ValueError says what is missing or from another version."""
    path = Path(path)
    files: dict[str, str] = {}
    try:
        if path.is_dir():
            for name in ("study.json", "beliefs.csv"):
                if (path / name).exists():
                    files[name] = (path / name).read_text(encoding="utf-8")
        elif zipfile.is_zipfile(path):
            with zipfile.ZipFile(path) as archive:
                for name in ("study.json", "beliefs.csv"):
                    if name in archive.namelist():
                        files[name] = archive.read(name).decode("utf-8")
        else:
            raise ValueError(f"{path} is neither a folder nor a zip file; expected a study's exports.zip or "
                             "the folder it unpacks to")
    except (OSError, UnicodeDecodeError, zipfile.BadZipFile) as exc:
        raise ValueError(f"cannot read the export {path}: {exc}") from None
    missing = [name for name in ("study.json", "beliefs.csv") if name not in files]
    if missing:
        raise ValueError(f"{path} has no {' and no '.join(missing)}; expected a study's exports.zip (or its folder)")
    try:
        study = json.loads(files["study.json"])
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: study.json is not JSON ({exc})") from None
    absent = [key for key in STUDY_KEYS if not isinstance(study, dict) or key not in study]
    reader = csv.DictReader(io.StringIO(files["beliefs.csv"]))
    columns = [c for c in BELIEF_COLUMNS if c not in (reader.fieldnames or [])]
    if absent or columns:
        what = [f"study.json lacks {', '.join(absent)}"] if absent else []
        what += [f"beliefs.csv lacks the columns {', '.join(columns)}"] if columns else []
        raise ValueError(f"{path} is an export from another version ({'; '.join(what)}); expected one written by "
                         "this version of tableteach")
    try:
        check_flip_rate(study.get("flip_rate", 0.0), "study.json flip_rate")
    except ValueError as exc:
        raise ValueError(f"{path} is not an export of this version: {exc}") from None
    return Export(study, list(reader))


def study_flip_rate(export: Export) -> float:
    """The study's own learner's flip rate (0, the authors' learner, in exports of studies without one)."""
    return float(export.study.get("flip_rate", 0.0))


def sessions(export: Export) -> dict[tuple[str, int], list[dict[str, str]]]:
    """beliefs.csv rows per (participant, task index), in step order."""
    out: dict[tuple[str, int], list[dict[str, str]]] = {}
    for row in export.beliefs:
        out.setdefault((row["participant_id"], int(row["task_index"])), []).append(row)
    for rows in out.values():
        rows.sort(key=lambda r: int(r["step"]))
    return out


def _verdicts(rows: Sequence[dict[str, str]]) -> Verdicts:
    """(trace, acceptable, is_verdict) of every recorded step after the prior row."""
    out = []
    for row in rows:
        if row["record_kind"] == "":
            continue
        trace: Trace = tuple(frozenset(state) for state in json.loads(row["trace"]))
        out.append((trace, row["acceptable"] in ("True", "true", "1"), row["record_kind"] == "query"))
    return tuple(out)


def replay(export: Export, learners: Sequence[LearnerSpec]) -> Iterator[dict[str, Any]]:
    """One row per participant, task, step and learner: what that learner believes after the same data."""
    own = export.study.get("objects")  # a study with its own objects: its formulas are over them
    task = "dinner" if not own else objects_task(tuple(o["name"] for o in own))
    domain = get_domain(task)
    tasks = export.study["tasks"]
    for (participant, task_index), rows in sorted(sessions(export).items(), key=_session_order):
        truth_text = tasks[task_index].get("ground_truth")
        truth = None if truth_text is None else domain.clause_space.mask_of_formula(truth_text)
        data = _verdicts(rows)
        for learner in learners:
            views = step_views(learner, data, truth, task=task, study_prior=export.study["prior"],
                               study_flip_rate=study_flip_rate(export))
            for row in rows:
                view = views[int(row["step"])]
                yield {"participant_id": participant, "condition": row["condition"], "task_index": task_index,
                       "task": row["task"], "step": view["step"], "record_kind": row["record_kind"],
                       "learner": learner.name, "similarity": view["similarity"], "entropy": view["entropy"],
                       "map_formula": view["map_formula"],
                       "study_similarity": row["similarity"], "study_entropy": row["entropy"],
                       "study_map_formula": row["map_formula"]}


def _session_order(item: tuple[tuple[str, int], Any]) -> tuple[int, str, int]:
    participant, task_index = item[0]
    return (int(participant) if participant.isdigit() else 0, participant, task_index)
