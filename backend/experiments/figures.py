"""Figures of a sweep (matplotlib, Agg backend), each written as PNG and SVG.

- by_n_query_{median,mean}: entropy (left) and similarity (right) at the final step against
  n_query, one line per protocol with 95% bootstrap CI bars, like the paper's figure;
- learning_curve: mean similarity and entropy against the number of executions seen, for the
  largest n_query, with 95% bootstrap CI bands.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from ..core.session import PROTOCOLS
from .settings import ExperimentSettings  # noqa: E402
from .summary import SummaryRow, bootstrap_ci, group_rng  # noqa: E402

COLORS = {"active": "#1b6ca8", "random": "#e08a00", "batch": "#4a9a3d"}
LABELS = {"active": "Active", "random": "Random", "batch": "Batch"}
PANELS = (("entropy", "Entropy (nats)"), ("similarity", "Similarity to ground truth"))
_CURVE_STREAM = 2  # bootstrap stream of the learning curve, apart from the summary's


def _save(fig: plt.Figure, stem: Path) -> list[Path]:
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    fig.savefig(paths[0], dpi=110, metadata={"Software": None})  # modest files: figures are committed
    with plt.rc_context({"svg.hashsalt": "tableteach"}):  # stable element ids: reruns give identical SVGs
        fig.savefig(paths[1], metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return paths


def _title(settings: ExperimentSettings) -> str:
    return (f"{settings.domain}, prior {settings.prior}, truth {settings.truth_sampler}, "
            f"{settings.runs} runs, noise {settings.noise:g}, {settings.demo_mode} demonstrations"
            + ("" if settings.query_ties == "uniform" else f", {settings.query_ties} query ties")
            + ("" if settings.similarity == "authors" else f", {settings.similarity} similarity"))


def plot_by_n_query(summary: Sequence[SummaryRow], settings: ExperimentSettings, statistic: str,
                    stem: Path) -> list[Path]:
    """Entropy (left) and similarity (right) against n_query, one line per protocol with CI bars."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    offsets = dict(zip(PROTOCOLS, (-0.08, 0.0, 0.08), strict=True))  # dodge so the CI bars do not overlap
    for ax, (metric, label) in zip(axes, PANELS, strict=True):
        for protocol in PROTOCOLS:
            rows = [r for r in summary if r.protocol == protocol]
            if not rows:
                continue
            x = np.array([r.n_query for r in rows]) + offsets[protocol]
            y = np.array([r.stats[f"{metric}_{statistic}"] for r in rows])
            low = np.array([r.stats[f"{metric}_{statistic}_lo"] for r in rows])
            high = np.array([r.stats[f"{metric}_{statistic}_hi"] for r in rows])
            ax.errorbar(x, y, yerr=[y - low, high - y], marker="o", capsize=3, color=COLORS[protocol],
                        label=LABELS[protocol])
        ax.set_xlabel("n_query (queries, or extra demonstrations for Batch)")
        ax.set_ylabel(f"{label}, {statistic} over runs")
        ax.set_xticks(list(settings.n_query))
        ax.grid(alpha=0.3)
    axes[1].legend()
    fig.suptitle(f"Final step, {statistic} with 95% bootstrap CI: {_title(settings)}", fontsize=9)
    return _save(fig, stem)


def plot_learning_curve(rows: Sequence[dict[str, str]], settings: ExperimentSettings, stem: Path) -> list[Path]:
    """Mean similarity and entropy against executions seen (largest n_query), 95% CI bands."""
    n_query = settings.max_n_query
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for ax, (metric, label) in zip(axes[::-1], PANELS, strict=True):
        for p, protocol in enumerate(PROTOCOLS):
            by_step: dict[int, list[float]] = {}
            for row in rows:
                if row["protocol"] == protocol and int(row["n_query"]) == n_query:
                    by_step.setdefault(int(row["n_executions"]), []).append(float(row[metric]))
            if not by_step:
                continue
            steps = sorted(by_step)
            stats = [bootstrap_ci(np.array(by_step[k]), "mean", group_rng(settings.seed, _CURVE_STREAM, p, k))
                     for k in steps]
            mean, low, high = (np.array(v) for v in zip(*stats, strict=True))
            ax.plot(steps, mean, marker="o", color=COLORS[protocol], label=LABELS[protocol])
            ax.fill_between(steps, low, high, color=COLORS[protocol], alpha=0.2)
        ax.axvline(settings.n_demonstrations, color="grey", linestyle=":", linewidth=1)
        ax.set_xlabel("executions seen (demonstrations, then queries)")
        ax.set_ylabel(f"{label}, mean over runs")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle(f"Learning curve, n_query = {n_query}: {_title(settings)}", fontsize=9)
    return _save(fig, stem)


def write_figures(summary: Sequence[SummaryRow], rows: Sequence[dict[str, str]], settings: ExperimentSettings,
                  folder: Path) -> list[Path]:
    """Every figure of a sweep, as PNG and SVG; returns the paths written."""
    paths: list[Path] = []
    for statistic in ("median", "mean"):
        paths += plot_by_n_query(summary, settings, statistic, folder / f"by_n_query_{statistic}")
    paths += plot_learning_curve(rows, settings, folder / "learning_curve")
    return paths
