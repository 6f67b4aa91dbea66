"""The ``tableteach replay`` subcommand: a study's sessions replayed through other learners (replay.csv, figure)."""

from __future__ import annotations

import argparse
import csv
import sys
import textwrap
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from tqdm import tqdm

from .replay import REPLAY_COLUMNS, parse_learners, read_export, replay, sessions

DESCRIPTION = """Replay every participant's recorded demonstrations and verdicts through each learner SPEC:
'study' (the study's own settings) or settings prior=NAME, flip=P (noise-aware, P in [0, 0.5); flip=0 is
the authors' learner), data=demonstrations (Batch from the same demonstrations), comma-separated; unset
settings are the study's. Writes replay.csv (per
participant, task, step and learner: similarity to the ground truth, entropy, MAP formula, next to the
study's robot) and replay.png/.svg (per participant and task, each learner's final similarity minus the
study robot's) into --out."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``replay`` subcommand."""
    p = subparsers.add_parser("replay", help="replay a study's sessions through other learners",
                              description=DESCRIPTION)
    p.add_argument("export", help="a study's exports.zip, or the folder it unpacks to")
    p.add_argument("--learner", action="append", required=True, metavar="SPEC",
                   help="a learner to replay (repeatable), e.g. study, flip=0.1, data=demonstrations, "
                        "prior=chains-2020,flip=0.2")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_replay)


def cmd_replay(args: argparse.Namespace) -> dict[str, Any]:
    """Replay, write replay.csv and the figure; print what was written."""
    learners = parse_learners(args.learner)
    names = [learner.name for learner in learners]
    export = read_export(args.export)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot create --out {out}: {exc.strerror or exc}") from None
    n_sessions = len(sessions(export))
    rows = []
    with tqdm(total=len(export.beliefs) * len(learners), unit="step",
              desc="replay", file=sys.stderr, disable=args.no_progress, dynamic_ncols=True) as bar:
        for row in replay(export, learners):
            rows.append(row)
            bar.update(1)
    write_replay_csv(out / "replay.csv", rows)
    figures = plot_replay(rows, [n for n in names if n != "study"], f"{export.study.get('name', 'study')}: "
                          "each learner's final similarity minus the study robot's", out / "replay")
    return {"out": str(out), "sessions": n_sessions, "learners": names, "rows": len(rows),
            "files": ["replay.csv", *[p.name for p in figures]],
            "final_similarity_median": _final_medians(rows, names)}


def write_replay_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """replay.csv, floats at full precision (a replay with the study's settings must match beliefs.csv)."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(REPLAY_COLUMNS), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


def final_rows(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, str, int], dict[str, Any]]:
    """The last step of each (learner, participant, task)."""
    out: dict[tuple[str, str, int], dict[str, Any]] = {}
    for row in rows:
        key = (row["learner"], row["participant_id"], row["task_index"])
        if key not in out or row["step"] > out[key]["step"]:
            out[key] = row
    return out


def _final_medians(rows: Sequence[dict[str, Any]], names: Sequence[str]) -> dict[str, float | None]:
    finals = final_rows(rows)
    out: dict[str, float | None] = {}
    for name in names:
        values = [r["similarity"] for k, r in finals.items() if k[0] == name and r["similarity"] is not None]
        out[name] = round(float(np.median(values)), 3) if values else None
    return out


def plot_replay(rows: Sequence[dict[str, Any]], names: Sequence[str], title: str, stem: Path) -> list[Path]:
    """Per learner, one dot per participant and task: final similarity minus the study robot's; median bar."""
    from .figures import _save, plt

    finals = final_rows(rows)
    fig, ax = plt.subplots(figsize=(max(4.5, 1.6 * len(names) + 2), 4), constrained_layout=True)
    rng = np.random.default_rng(0)  # horizontal jitter only
    for i, name in enumerate(names):
        diffs = np.array([r["similarity"] - float(r["study_similarity"]) for k, r in finals.items()
                          if k[0] == name and r["similarity"] is not None and r["study_similarity"] not in ("", None)])
        if diffs.size == 0:
            continue
        ax.scatter(i + rng.uniform(-0.15, 0.15, diffs.size), diffs, s=18, alpha=0.7, color="#1b6ca8")
        ax.hlines(np.median(diffs), i - 0.3, i + 0.3, color="black", linewidth=2)
    ax.axhline(0.0, color="grey", linewidth=0.8)
    ax.set_xticks(range(len(names)), names, rotation=15)
    ax.set_xlim(-0.6, max(len(names), 1) - 0.4)
    ax.set_ylabel("final similarity, learner − study robot\n(one dot per participant and task; bar: median)")
    ax.grid(alpha=0.3, axis="y")
    fig.suptitle(textwrap.fill(title, 80), fontsize=9)
    return _save(fig, stem)
