"""Paired differences between two sweeps of the same runs that differ in one learner setting.

Two sweeps with the same seed, domain, prior, truth sampler and demonstrator share every run's
ground truth and first demonstrations, so a protocol's final similarity in sweep B minus sweep A,
run by run, is a paired difference (e.g. information-gain queries minus uncertainty sampling).
"""

from __future__ import annotations

import textwrap

from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.session import PROTOCOLS
from .settings import ExperimentSettings
from .summary import bootstrap_ci, final_values, group_rng

SHARED_SETTINGS = ("seed", "domain", "prior", "truth_sampler", "demo_mode", "similarity", "n_demonstrations")
PAIRED_SWEEP_COLUMNS = ("protocol", "n_query", "runs", "a_median", "b_median", "diff_mean", "diff_mean_lo",
                        "diff_mean_hi", "diff_median", "diff_median_lo", "diff_median_hi", "share_better",
                        "share_equal", "share_worse")
_STREAM = 4  # bootstrap stream apart from the summary's (1), the learning curve's (2) and the study's (3)


def check_pairable(a: ExperimentSettings, b: ExperimentSettings) -> None:
    """ValueError naming every setting that makes the two sweeps' runs differ in truth or demonstrations."""
    differ = [f"{k}: {getattr(a, k)!r} vs {getattr(b, k)!r}" for k in SHARED_SETTINGS if getattr(a, k) != getattr(b, k)]
    if differ:
        raise ValueError(f"the two sweeps do not share their runs ({'; '.join(differ)}); expected sweeps that "
                         "differ only in a learner setting")


def paired_sweep_differences(a: ExperimentSettings, rows_a: Sequence[dict[str, str]], b: ExperimentSettings,
                             rows_b: Sequence[dict[str, str]], protocols: Sequence[str] = PROTOCOLS,
                             ) -> list[dict[str, object]]:
    """Per protocol and shared n_query: B's final similarity minus A's, paired by run, with 95% bootstrap CIs."""
    check_pairable(a, b)
    va, vb = final_values(rows_a, a), final_values(rows_b, b)
    runs = min(a.runs, b.runs)
    out: list[dict[str, object]] = []
    for p, protocol in enumerate(protocols):
        for n_query in sorted(set(a.n_query) & set(b.n_query)):
            if (protocol, n_query) not in va or (protocol, n_query) not in vb:
                continue
            sa, sb = va[(protocol, n_query)]["similarity"][:runs], vb[(protocol, n_query)]["similarity"][:runs]
            diff = sb - sa
            mean = bootstrap_ci(diff, "mean", group_rng(a.seed, _STREAM, p, n_query, 0))
            med = bootstrap_ci(diff, "median", group_rng(a.seed, _STREAM, p, n_query, 1))
            out.append({"protocol": protocol, "n_query": n_query, "runs": int(diff.size),
                        "a_median": float(np.median(sa)), "b_median": float(np.median(sb)),
                        "diff_mean": mean[0], "diff_mean_lo": mean[1], "diff_mean_hi": mean[2],
                        "diff_median": med[0], "diff_median_lo": med[1], "diff_median_hi": med[2],
                        "share_better": float(np.mean(diff > 1e-9)), "share_equal": float(np.mean(abs(diff) <= 1e-9)),
                        "share_worse": float(np.mean(diff < -1e-9))})
    return out


def plot_paired_sweeps(table: Sequence[dict[str, object]], label: str, title: str, stem: Path) -> list[Path]:
    """Mean paired difference (95% CI) against n_query, one line per protocol, with the zero line."""
    from .figures import COLORS, LABELS, _save, plt

    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    for protocol in PROTOCOLS:
        mine = [r for r in table if r["protocol"] == protocol]
        if not mine:
            continue
        x = np.array([r["n_query"] for r in mine], dtype=float)
        y = np.array([r["diff_mean"] for r in mine], dtype=float)
        err = [y - np.array([r["diff_mean_lo"] for r in mine]), np.array([r["diff_mean_hi"] for r in mine]) - y]
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3, color=COLORS[protocol], label=LABELS[protocol])
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xlabel("n_query")
    ax.set_ylabel("\n".join(textwrap.wrap(f"final similarity, {label}", 45)) + "\n(paired mean, 95% CI)",
                  fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.suptitle(textwrap.fill(title, 80), fontsize=9)
    return _save(fig, stem)
