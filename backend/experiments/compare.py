"""Figures and tables across finished sweeps: the user study in simulation and the fallible teacher.

    python -m tableteach.experiments.compare user-study --task1 DIR --task2 DIR --out DIR
    python -m tableteach.experiments.compare noise DIR [DIR ...] --n-query 6 --out DIR
    python -m tableteach.experiments.compare paired A_DIR B_DIR --label "information gain - uncertainty" --out DIR
    python -m tableteach.experiments.compare sizes DIR [DIR ...] --out DIR

Each DIR is a sweep folder written by ``tableteach experiment`` (runs.csv and config.json).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.session import PROTOCOLS
from .summary import bootstrap_ci, group_rng, weighted_bootstrap_ci, write_csv

# The paper's user study: median final similarity after 2 demonstrations + 3 queries; its pooled median
# is over 21 Task 1 and 6 Task 2 participants, so "both-paper" weighs the tasks 21:6 ("both": 50:50).
PAPER_STUDY_MEDIANS = {"task1": 0.87, "task2": 0.78, "both-paper": 0.83}
PAPER_STUDY_PARTICIPANTS = {"task1": 21, "task2": 6}
STUDY_TASKS = ("task1", "task2", "both", "both-paper")
STUDY_TITLES = {"task1": "Task 1", "task2": "Task 2", "both": "both tasks, 50:50",
                "both-paper": "both tasks, 21:6 (the paper's participants)"}
_STREAM = 3  # bootstrap stream apart from the summary's and the learning curve's


def read_sweep(folder: Path | str) -> tuple[dict, list[dict[str, str]]]:
    """A finished sweep's settings and rows; ValueError names a folder that is not one."""
    folder = Path(folder)
    try:
        config = json.loads((folder / "config.json").read_text(encoding="utf-8"))
        with open(folder / "runs.csv", encoding="utf-8", newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{folder} is not a finished sweep folder ({exc}); expected config.json and runs.csv "
                         "written by tableteach experiment") from None
    return config["settings"], rows


def study_curves(task_rows: dict[str, list[dict[str, str]]], n_query: int, n_demonstrations: int,
                 seed: int = 0) -> list[dict[str, object]]:
    """Per task (both pooled too), protocol and executions seen from the last demonstration on: median
    similarity and mean entropy with 95% bootstrap CIs."""
    out: list[dict[str, object]] = []
    pooled = {"both": [r for t in ("task1", "task2") for r in task_rows[t]],
              "both-paper": [r for t in ("task1", "task2") for r in task_rows[t]], **task_rows}
    for t, task in enumerate(STUDY_TASKS):
        if task == "both-paper":
            out += _weighted_curves(task_rows, n_query, n_demonstrations, seed, t)
            continue
        rows = [r for r in pooled[task] if int(r["n_query"]) == n_query and int(r["n_executions"]) >= n_demonstrations]
        for p, protocol in enumerate(PROTOCOLS):
            mine = [r for r in rows if r["protocol"] == protocol]
            for k in sorted({int(r["n_executions"]) for r in mine}):
                step = [r for r in mine if int(r["n_executions"]) == k]
                sim = bootstrap_ci(np.array([float(r["similarity"]) for r in step]), "median",
                                   group_rng(seed, _STREAM, t, p, k, 0))
                ent = bootstrap_ci(np.array([float(r["entropy"]) for r in step]), "mean",
                                   group_rng(seed, _STREAM, t, p, k, 1))
                out.append({"task": task, "protocol": protocol, "n_executions": k, "runs": len(step),
                            "similarity_median": sim[0], "similarity_median_lo": sim[1],
                            "similarity_median_hi": sim[2], "entropy_mean": ent[0], "entropy_mean_lo": ent[1],
                            "entropy_mean_hi": ent[2]})
    return out


def _weighted_curves(task_rows: dict[str, list[dict[str, str]]], n_query: int, n_demonstrations: int, seed: int,
                     t: int) -> list[dict[str, object]]:
    """The two tasks pooled with the weights of the paper's participants (21:6), CIs resampled within each task."""
    out: list[dict[str, object]] = []
    shares = [PAPER_STUDY_PARTICIPANTS["task1"], PAPER_STUDY_PARTICIPANTS["task2"]]
    for p, protocol in enumerate(PROTOCOLS):
        per_task = [[r for r in task_rows[task] if r["protocol"] == protocol and int(r["n_query"]) == n_query
                     and int(r["n_executions"]) >= n_demonstrations] for task in ("task1", "task2")]
        for k in sorted({int(r["n_executions"]) for r in per_task[0]} & {int(r["n_executions"]) for r in per_task[1]}):
            steps = [[r for r in rows if int(r["n_executions"]) == k] for rows in per_task]
            sim = weighted_bootstrap_ci([np.array([float(r["similarity"]) for r in s]) for s in steps], shares,
                                        "median", group_rng(seed, _STREAM, t, p, k, 0))
            ent = weighted_bootstrap_ci([np.array([float(r["entropy"]) for r in s]) for s in steps], shares,
                                        "mean", group_rng(seed, _STREAM, t, p, k, 1))
            out.append({"task": "both-paper", "protocol": protocol, "n_executions": k,
                        "runs": sum(len(s) for s in steps), "similarity_median": sim[0],
                        "similarity_median_lo": sim[1], "similarity_median_hi": sim[2], "entropy_mean": ent[0],
                        "entropy_mean_lo": ent[1], "entropy_mean_hi": ent[2]})
    return out


STUDY_COLUMNS = ("task", "protocol", "n_executions", "runs", "similarity_median", "similarity_median_lo",
                 "similarity_median_hi", "entropy_mean", "entropy_mean_lo", "entropy_mean_hi")


def plot_study(curves: Sequence[dict[str, object]], title: str, stem: Path) -> list[Path]:
    """Median similarity (top) and mean entropy (bottom) against executions seen, one column per task."""
    from .figures import COLORS, LABELS, _save, plt

    fig, axes = plt.subplots(2, len(STUDY_TASKS), figsize=(15, 6.5), sharex=True, sharey="row", constrained_layout=True)
    for col, task in enumerate(STUDY_TASKS):
        for protocol in PROTOCOLS:
            mine = [c for c in curves if c["task"] == task and c["protocol"] == protocol]
            if not mine:
                continue
            x = np.array([c["n_executions"] for c in mine], dtype=float)
            for row, metric in enumerate(("similarity_median", "entropy_mean")):
                y = np.array([c[metric] for c in mine], dtype=float)
                low = np.array([c[f"{metric}_lo"] for c in mine], dtype=float)
                high = np.array([c[f"{metric}_hi"] for c in mine], dtype=float)
                ax = axes[row, col]
                ax.plot(x, y, marker="o", color=COLORS[protocol], label=LABELS[protocol])
                ax.fill_between(x, low, high, color=COLORS[protocol], alpha=0.2)
        last = max(c["n_executions"] for c in curves)
        if task in PAPER_STUDY_MEDIANS:  # the paper pooled its participants 21:6, not 50:50
            axes[0, col].plot([last], [PAPER_STUDY_MEDIANS[task]], marker="*", markersize=14, color="black",
                              linestyle="none", label="paper's user study (Active)")
        axes[0, col].set_title(STUDY_TITLES[task], fontsize=10)
        axes[1, col].set_xlabel("executions seen (demonstrations, then queries)")
        axes[1, col].set_xticks(sorted({int(c["n_executions"]) for c in curves}))
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("similarity, median (95% CI)")
    axes[1, 0].set_ylabel("entropy (nats), mean (95% CI)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    return _save(fig, stem)


def noise_table(folders: Sequence[Path | str], n_query: int) -> list[dict[str, object]]:
    """Per noise level and protocol: final median similarity and mean test success (with CIs)."""
    out: list[dict[str, object]] = []
    for folder in folders:
        settings = read_settings(folder)
        with open(Path(folder) / "summary.csv", encoding="utf-8", newline="") as f:
            summary = [r for r in csv.DictReader(f) if int(r["n_query"]) == n_query]
        if not summary:
            raise ValueError(f"{folder} has no rows for n_query {n_query}; expected one of {settings['n_query']}")
        for r in summary:
            if r["test_success_mean"] == "nan":
                raise ValueError(f"{folder} did not measure test success; expected a sweep run with --test-success")
            out.append({"noise": float(settings["noise"]), "learner": learner_name(settings),
                        "protocol": r["protocol"], "n_query": n_query,
                        **{k: float(r[k]) for k in ("similarity_median", "similarity_median_lo", "similarity_median_hi",
                                                    "test_success_mean", "test_success_mean_lo",
                                                    "test_success_mean_hi")}})
    return sorted(out, key=lambda r: (PROTOCOLS.index(r["protocol"]), r["learner"] != "authors", r["noise"]))


def read_settings(folder: Path | str) -> dict:
    """A sweep folder's settings (config.json only: committed folders keep no runs.csv)."""
    try:
        return json.loads((Path(folder) / "config.json").read_text(encoding="utf-8"))["settings"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ValueError(f"{folder} is not a sweep folder ({exc}); expected config.json written by "
                         "tableteach experiment") from None


def learner_name(settings: dict) -> str:
    """'authors' for the authors' learner, else 'noise-aware' (it assumes the sweep's verdict-flip rate)."""
    return "noise-aware" if float(settings.get("learner_flip_rate", 0.0)) > 0 else "authors"


NOISE_COLUMNS = ("noise", "learner", "protocol", "n_query", "similarity_median", "similarity_median_lo",
                 "similarity_median_hi", "test_success_mean", "test_success_mean_lo", "test_success_mean_hi")


def plot_noise(table: Sequence[dict[str, object]], title: str, stem: Path) -> list[Path]:
    """Final median similarity (left) and test success (right) against the teacher's flip probability."""
    from .figures import COLORS, LABELS, _save, plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    panels = (("similarity_median", "similarity, median (95% CI)"),
              ("test_success_mean", "robot test executions acceptable (share, 95% CI)"))
    for ax, (metric, label) in zip(axes, panels, strict=True):
        for protocol in PROTOCOLS:
            for learner, style in (("authors", "-"), ("noise-aware", "--")):
                mine = [r for r in table if r["protocol"] == protocol and r["learner"] == learner]
                if not mine or (learner == "noise-aware" and protocol == "batch"):  # Batch sees no verdicts
                    continue
                x = np.array([r["noise"] for r in mine], dtype=float)
                y = np.array([r[metric] for r in mine], dtype=float)
                err = [y - np.array([r[f"{metric}_lo"] for r in mine]),
                       np.array([r[f"{metric}_hi"] for r in mine]) - y]
                name = LABELS[protocol] + (", noise-aware learner" if learner == "noise-aware" else "")
                ax.errorbar(x, y, yerr=err, marker="o" if learner == "authors" else "s", capsize=3, linestyle=style,
                            color=COLORS[protocol], label=name)
        ax.set_xlabel("probability that the teacher flips a verdict (--noise)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    return _save(fig, stem)


SIZE_COLUMNS = ("waypoints", "threats", "comparison", "n_query", "runs", "similarity_diff_mean",
                "similarity_diff_mean_lo", "similarity_diff_mean_hi", "share_better")


def size_table(folders: Sequence[Path | str]) -> list[dict[str, object]]:
    """Active's paired advantage in final similarity (paired.csv) of synthetic sweeps of several sizes."""
    out: list[dict[str, object]] = []
    for folder in folders:
        settings = read_settings(folder)
        if settings.get("domain") != "synthetic":
            raise ValueError(f"{folder} is a {settings.get('domain')} sweep; expected synthetic sweeps of "
                             "several sizes")
        try:
            with open(Path(folder) / "paired.csv", encoding="utf-8", newline="") as f:
                rows = list(csv.DictReader(f))
        except OSError as exc:
            raise ValueError(f"{folder} has no paired.csv ({exc}); expected a finished sweep") from None
        for r in rows:
            out.append({"waypoints": int(settings.get("n_waypoints", 5)), "threats": int(settings.get("n_threats", 5)),
                        "comparison": r["comparison"], "n_query": int(r["n_query"]), "runs": int(r["runs"]),
                        **{k: float(r[k]) for k in SIZE_COLUMNS[5:]}})
    return sorted(out, key=lambda r: (r["comparison"], r["waypoints"], r["threats"], r["n_query"]))


def plot_sizes(table: Sequence[dict[str, object]], title: str, stem: Path) -> list[Path]:
    """Active minus Batch (left) and minus Random (right), paired mean final similarity, against n_query."""
    from .figures import _save, plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True, sharey=True)
    sizes = sorted({(r["waypoints"], r["threats"]) for r in table})
    for ax, comparison in zip(axes, ("active-batch", "active-random"), strict=True):
        for k, (w, t) in enumerate(sizes):
            mine = [r for r in table if r["comparison"] == comparison and (r["waypoints"], r["threats"]) == (w, t)]
            x = np.array([r["n_query"] for r in mine], dtype=float) + (k - (len(sizes) - 1) / 2) * 0.08
            y = np.array([r["similarity_diff_mean"] for r in mine], dtype=float)
            err = [y - np.array([r["similarity_diff_mean_lo"] for r in mine], dtype=float),
                   np.array([r["similarity_diff_mean_hi"] for r in mine], dtype=float) - y]
            runs = mine[0]["runs"] if mine else 0
            ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=f"{w} waypoints + {t} threats ({runs} runs)")
        ax.axhline(0.0, color="grey", linewidth=0.8)
        ax.set_xlabel("queries (n_query)")
        ax.set_title(comparison.replace("-", " minus ").capitalize(), fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("paired difference, final similarity (mean, 95% CI)")
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    return _save(fig, stem)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: build the user-study or noise figure and table from finished sweeps."""
    parser = argparse.ArgumentParser(prog="python -m tableteach.experiments.compare", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    study = sub.add_parser("user-study", help="learning curves of Task 1 and Task 2 next to the paper's medians")
    study.add_argument("--task1", required=True)
    study.add_argument("--task2", required=True)
    study.add_argument("--out", required=True)
    noise = sub.add_parser("noise", help="final similarity and test success against the teacher's noise")
    noise.add_argument("folders", nargs="+")
    noise.add_argument("--n-query", type=int, required=True)
    noise.add_argument("--out", required=True)
    paired = sub.add_parser("paired", help="B minus A, paired by run, for two sweeps of the same runs that "
                                           "differ in a learner setting")
    paired.add_argument("a")
    paired.add_argument("b")
    paired.add_argument("--label", default="B - A", help="what the difference is, for the figure")
    paired.add_argument("--protocol", action="append", choices=list(PROTOCOLS),
                        help="only this protocol (repeatable; default all)")
    paired.add_argument("--out", required=True)
    sizes = sub.add_parser("sizes", help="Active's paired advantage in synthetic sweeps of several sizes")
    sizes.add_argument("folders", nargs="+")
    sizes.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        if args.what == "user-study":
            (s1, rows1), (_, rows2) = read_sweep(args.task1), read_sweep(args.task2)
            n_query = max(s1["n_query"])
            curves = study_curves({"task1": rows1, "task2": rows2}, n_query, s1["n_demonstrations"])
            write_csv(out / "user_study.csv", curves, STUDY_COLUMNS)
            title = (f"User study in simulation: dinner table, 2 demonstrations + {n_query} queries, prior "
                     f"{s1['prior']}, {s1['demo_mode']} demonstrations, {s1['runs']} runs per task")
            plot_study(curves, title, out / "user_study")
        elif args.what == "sizes":
            table = size_table(args.folders)
            write_csv(out / "sizes.csv", table, SIZE_COLUMNS)
            plot_sizes(table, "Does Active's advantage grow with the size of the task? Synthetic domain, "
                       "paired by run (same truth and demonstrations)", out / "sizes")
        elif args.what == "paired":
            from .paired_sweeps import PAIRED_SWEEP_COLUMNS, paired_sweep_differences, plot_paired_sweeps
            from .settings import ExperimentSettings

            (sa, ra), (sb, rb) = read_sweep(args.a), read_sweep(args.b)
            a, b = ExperimentSettings.from_json(sa), ExperimentSettings.from_json(sb)
            table = paired_sweep_differences(a, ra, b, rb, args.protocol or PROTOCOLS)
            write_csv(out / "paired_sweeps.csv", table, PAIRED_SWEEP_COLUMNS)
            title = f"{args.label}: {a.domain}, {min(a.runs, b.runs)} paired runs, seed {a.seed}"
            plot_paired_sweeps(table, args.label, title, out / "paired_sweeps")
        else:
            table = noise_table(args.folders, args.n_query)
            write_csv(out / "noise.csv", table, NOISE_COLUMNS)
            settings = read_settings(args.folders[0])
            runs = "/".join(sorted({str(read_settings(f)["runs"]) for f in args.folders}, key=int))
            title = (f"Fallible teacher: {settings['domain']}, n_query {args.n_query}, {runs} runs, "
                     f"{settings['demo_mode']} demonstrations (demonstrations are never noisy)")
            plot_noise(table, title, out / "noise")
    except ValueError as exc:
        print(f"compare: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
