"""Does the teacher-consistency score separate fallible teachers from perfect ones? A simulation.

    python -m tableteach.experiments.teacher_consistency --runs 100 --flip 0.2 --out DIR

Each run draws a dinner-table ground truth from the prior and plays the study's protocol (the real
session state machine: 2 demonstrations, 3 queries, 3 tests, Active or Random) twice with the same
truth, demonstrations and seed: once with a perfect teacher, once with one who flips each verdict with
probability --flip. Every verdict (queries and tests) gets the probability the learner gave it just
before; a teacher's score is their mean. Writes consistency_scores.csv (one row per run and teacher),
consistency_auc.csv, consistency_flags.csv (the share of each teacher the dashboard's flag marks: a verdict
with probability below core.consistency.FLAG_BELOW) and consistency_roc.png/.svg.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from tqdm import tqdm

from ..core import session as core
from ..core.belief import check_flip_rate
from ..core.consistency import FLAG_BELOW, auc, consistency_score, session_verdict_probabilities
from ..core.domain import get_domain
from ..core.hypotheses import get_space
from ..core.priors import DEFAULT_PRIOR
from ..core.teachers import SimulatedTeacher, sample_ground_truth


def teach(config: core.SessionConfig, teacher: SimulatedTeacher, rng_seed: int) -> core.SessionState:
    """A whole session of the protocol taught by a simulated teacher."""
    demo_rng, verdict_rng = np.random.default_rng([rng_seed, 0]), np.random.default_rng([rng_seed, 1])
    state = core.start(config)
    while state.phase != "done":
        step = core.next_step(state)
        if step.kind in ("practice", "demonstration"):
            state = core.observe(state, step.kind, teacher.demonstrate(demo_rng).trace)
        else:
            trace = step.robot_execution.trace  # type: ignore[union-attr]
            state = core.observe(state, step.kind, trace, teacher.assess(trace, verdict_rng))
    return state


def all_verdict_probabilities(state: core.SessionState) -> list[float]:
    """The probability of every verdict of a session (queries, then tests) just before it was given."""
    learning, tests = session_verdict_probabilities(state)
    return [p for p in learning if p is not None] + tests


def simulate(runs: int, flip: float, protocol: str, seed: int, progress: bool) -> list[dict[str, Any]]:
    """One row per run and teacher: the run's truth, the teacher's flip rate, verdicts and score."""
    domain = get_domain("dinner")
    space = get_space("dinner", DEFAULT_PRIOR)
    rows = []
    for run in tqdm(range(runs), unit="run", desc="runs", file=sys.stderr, disable=not progress):
        truth = sample_ground_truth(space, np.random.default_rng([seed, run, 2]))
        config = core.SessionConfig(task="dinner", protocol=protocol, n_practice=0, n_demonstrations=2, n_queries=3,
                                    n_tests=3, seed=(seed * 100_003 + run) % (2**31))
        for noise in (0.0, flip):
            teacher = SimulatedTeacher(domain, truth, noise=noise)
            probabilities = all_verdict_probabilities(teach(config, teacher, seed * 100_003 + run))
            rows.append({"run": run, "teacher_flip_rate": noise, "protocol": protocol,
                         "ground_truth": domain.clause_space.text_of(truth), "n_verdicts": len(probabilities),
                         "lowest_p_verdict": min(probabilities), "score": consistency_score(probabilities)})
    return rows


def flag_rates(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per teacher flip rate: how many teachers the flag marks (their lowest verdict probability below
    FLAG_BELOW) and the share."""
    out = []
    for noise in sorted({float(r["teacher_flip_rate"]) for r in rows}):
        lowest = [float(r["lowest_p_verdict"]) for r in rows if float(r["teacher_flip_rate"]) == noise]
        n = sum(p < FLAG_BELOW for p in lowest)
        out.append({"teacher_flip_rate": noise, "teachers": len(lowest), "flag_below": FLAG_BELOW, "flagged": n,
                    "share_flagged": n / len(lowest)})
    return out


def plot_roc(rows: Sequence[dict[str, Any]], flip: float, title: str, stem: Path) -> list[Path]:
    """ROC of 'flagged' (score below a threshold) as a detector of the fallible teacher."""
    from .figures import _save, plt

    perfect = np.array([r["score"] for r in rows if r["teacher_flip_rate"] == 0.0])
    fallible = np.array([r["score"] for r in rows if r["teacher_flip_rate"] == flip])
    thresholds = np.unique(np.concatenate([perfect, fallible, [np.inf]]))
    tpr = [float(np.mean(fallible < t)) for t in thresholds]
    fpr = [float(np.mean(perfect < t)) for t in thresholds]
    fig, ax = plt.subplots(figsize=(4.5, 4.2), constrained_layout=True)
    ax.plot([0.0, *fpr], [0.0, *tpr], color="#1b6ca8", marker=".")
    ax.plot([0, 1], [0, 1], color="grey", linewidth=0.8, linestyle="--")
    ax.set_xlabel("perfect teachers flagged (false positive rate)")
    ax.set_ylabel(f"flip-{flip:g} teachers flagged (true positive rate)")
    ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=9)
    return _save(fig, stem)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: simulate, write the scores, the AUC and the ROC figure."""
    parser = argparse.ArgumentParser(prog="python -m tableteach.experiments.teacher_consistency", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=100, help="runs, each with both teachers (default 100)")
    parser.add_argument("--flip", type=float, default=0.2, help="the fallible teacher's flip rate (default 0.2)")
    parser.add_argument("--protocol", choices=["active", "random"], default="active")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True)
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    try:
        check_flip_rate(args.flip, "--flip")
        if args.flip == 0.0 or args.runs < 1:
            raise ValueError("--flip must be above 0 and --runs at least 1: there is nothing to separate otherwise")
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        rows = simulate(args.runs, args.flip, args.protocol, args.seed, not args.no_progress)
    except (ValueError, OSError) as exc:
        print(f"teacher_consistency: error: {exc}", file=sys.stderr)
        return 2
    perfect = [r["score"] for r in rows if r["teacher_flip_rate"] == 0.0]
    fallible = [r["score"] for r in rows if r["teacher_flip_rate"] == args.flip]
    value = auc(perfect, fallible)
    with open(out / "consistency_scores.csv", "w", encoding="utf-8", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    with open(out / "consistency_auc.csv", "w", encoding="utf-8", newline="") as f:
        f.write("protocol,teacher_flip_rate,runs,auc,perfect_score_median,fallible_score_median\n")
        f.write(f"{args.protocol},{args.flip},{args.runs},{value:.4f},{np.median(perfect):.4f},"
                f"{np.median(fallible):.4f}\n")
    flags = flag_rates(rows)
    with open(out / "consistency_flags.csv", "w", encoding="utf-8", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(flags[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(flags)
    plot_roc(rows, args.flip, f"Teacher consistency, {args.protocol}, dinner table, {args.runs} runs: AUC {value:.3f}",
             out / "consistency_roc")
    print(f"AUC {value:.3f} (perfect vs flip {args.flip:g}, {args.runs} runs, {args.protocol}); flagged: "
          + ", ".join(f"{r['flagged']} of {r['teachers']} at flip {r['teacher_flip_rate']:g}" for r in flags))
    return 0


if __name__ == "__main__":
    sys.exit(main())
