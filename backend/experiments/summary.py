"""Summary statistics of a sweep: medians and means with seeded 95% bootstrap confidence intervals.

summary.csv: per protocol and n_query, the final step's statistics over runs.
paired.csv: per n_query, Active's final similarity minus Batch's and Random's in the same run.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..core.session import PROTOCOLS
from .settings import ExperimentSettings

METRICS = ("similarity", "entropy", "map_similarity", "test_success")  # test_success: nan when not measured
STATISTICS: dict[str, Callable[..., np.ndarray]] = {"median": np.median, "mean": np.mean}
N_BOOTSTRAP = 2000
CONFIDENCE = 0.95
CONFIDENT_NATS = 1.0
PAIRS = (("active", "batch"), ("active", "random"))
_BOOTSTRAP_STREAM = 1  # keeps the summary's random numbers apart from the runs' (which use [seed, run])


def bootstrap_ci(
    values: np.ndarray, statistic: str, rng: np.random.Generator, n_resamples: int = N_BOOTSTRAP
) -> tuple[float, float, float]:
    """(estimate, low, high): a statistic with its percentile-bootstrap 95% confidence interval."""
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return float("nan"), float("nan"), float("nan")
    fn = STATISTICS[statistic]
    resampled = fn(values[rng.integers(0, values.size, size=(n_resamples, values.size))], axis=1)
    alpha = (1.0 - CONFIDENCE) / 2.0
    low, high = np.quantile(resampled, [alpha, 1.0 - alpha])
    return float(fn(values)), float(low), float(high)


def weighted_statistic(groups: Sequence[np.ndarray], shares: Sequence[float], statistic: str) -> float:
    """A statistic of pooled groups in which group g carries the share shares[g] of the weight, whatever its size."""
    values = np.concatenate(groups)
    weights = np.concatenate([np.full(g.size, w / g.size) for g, w in zip(groups, shares, strict=True)])
    if statistic == "mean":
        return float(values @ weights / weights.sum())
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order]) / weights.sum()
    return float(values[order][np.searchsorted(cumulative, 0.5)])  # the lower weighted median


def weighted_bootstrap_ci(groups: Sequence[np.ndarray], shares: Sequence[float], statistic: str,
                          rng: np.random.Generator, n_resamples: int = N_BOOTSTRAP) -> tuple[float, float, float]:
    """(estimate, low, high) of ``weighted_statistic``, with a 95% bootstrap CI that resamples within each group."""
    groups = [np.asarray(g, dtype=np.float64) for g in groups]
    if any(g.size == 0 for g in groups):
        return float("nan"), float("nan"), float("nan")
    resampled = [weighted_statistic([g[rng.integers(0, g.size, g.size)] for g in groups], shares, statistic)
                 for _ in range(n_resamples)]
    alpha = (1.0 - CONFIDENCE) / 2.0
    low, high = np.quantile(resampled, [alpha, 1.0 - alpha])
    return weighted_statistic(groups, shares, statistic), float(low), float(high)


def group_rng(seed: int, *key: int) -> np.random.Generator:
    """The bootstrap generator of one group, independent of the order groups are summarised in."""
    return np.random.default_rng([seed, _BOOTSTRAP_STREAM, *key])


@dataclass(frozen=True)
class SummaryRow:
    """Final-step statistics of one protocol at one n_query."""

    protocol: str
    n_query: int
    runs: int
    stats: dict[str, float]

    def as_dict(self) -> dict[str, object]:
        """Flat form for the CSV."""
        return {"protocol": self.protocol, "n_query": self.n_query, "runs": self.runs, **self.stats}


def summary_columns() -> list[str]:
    """Column names of summary.csv."""
    cols = ["protocol", "n_query", "runs"]
    for metric in METRICS:
        for stat in STATISTICS:
            cols += [f"{metric}_{stat}", f"{metric}_{stat}_lo", f"{metric}_{stat}_hi"]
    return cols + ["map_exact", "confident_wrong"]


def final_values(rows: Sequence[dict[str, str]],
                 settings: ExperimentSettings) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """Per (protocol, n_query): each metric's values at the final learning step, ordered by run."""
    groups: dict[tuple[str, int], list[dict[str, str]]] = {}
    for row in rows:
        n_query = int(row["n_query"])
        if int(row["n_executions"]) == settings.n_demonstrations + n_query:
            groups.setdefault((row["protocol"], n_query), []).append(row)
    out: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    for key, members in groups.items():
        members.sort(key=lambda r: int(r["run"]))
        out[key] = {m: np.array([float(r[m]) if r[m] != "" else np.nan for r in members]) for m in METRICS}
    return out


def summarize(rows: Sequence[dict[str, str]], settings: ExperimentSettings) -> list[SummaryRow]:
    """Final-step summary per protocol and n_query (protocols in the paper's order)."""
    values = final_values(rows, settings)
    out: list[SummaryRow] = []
    for p, protocol in enumerate(PROTOCOLS):
        for n_query in settings.n_query:
            group = values.get((protocol, n_query))
            if group is None:
                continue
            stats: dict[str, float] = {}
            for m, metric in enumerate(METRICS):
                for s, stat in enumerate(STATISTICS):
                    if np.isnan(group[metric]).any():  # not measured in this sweep
                        est = low = high = float("nan")
                    else:
                        est, low, high = bootstrap_ci(group[metric], stat, group_rng(settings.seed, p, n_query, m, s))
                    stats.update({f"{metric}_{stat}": est, f"{metric}_{stat}_lo": low, f"{metric}_{stat}_hi": high})
            # Share of runs whose single most probable formula is exactly the truth (up to the metric).
            stats["map_exact"] = float(np.mean(group["map_similarity"] == 1.0))
            # Share of runs that are confident (entropy below CONFIDENT_NATS) yet whose MAP formula is wrong.
            confident = group["entropy"] < CONFIDENT_NATS
            stats["confident_wrong"] = float(np.mean(confident & (group["map_similarity"] < 1.0)))
            out.append(SummaryRow(protocol, n_query, int(group["similarity"].size), stats))
    return out


def paired_differences(rows: Sequence[dict[str, str]], settings: ExperimentSettings) -> list[dict[str, object]]:
    """Per n_query, Active minus Batch (and minus Random) final similarity, paired by run."""
    values = final_values(rows, settings)
    out: list[dict[str, object]] = []
    for n_query in settings.n_query:
        for k, (a, b) in enumerate(PAIRS):
            if (a, n_query) not in values or (b, n_query) not in values:
                continue
            diff = values[(a, n_query)]["similarity"] - values[(b, n_query)]["similarity"]
            mean, low, high = bootstrap_ci(diff, "mean", group_rng(settings.seed, len(PROTOCOLS) + k, n_query))
            med, med_low, med_high = bootstrap_ci(
                diff, "median", group_rng(settings.seed, len(PROTOCOLS) + len(PAIRS) + k, n_query)
            )
            out.append({
                "n_query": n_query, "comparison": f"{a}-{b}", "runs": int(diff.size),
                "similarity_diff_mean": mean, "similarity_diff_mean_lo": low, "similarity_diff_mean_hi": high,
                "similarity_diff_median": med, "similarity_diff_median_lo": med_low,
                "similarity_diff_median_hi": med_high,
                "share_better": float(np.mean(diff > 1e-9)), "share_equal": float(np.mean(np.abs(diff) <= 1e-9)),
                "share_worse": float(np.mean(diff < -1e-9)),
            })
    return out


def write_csv(path: Path, records: Sequence[dict[str, object]], columns: Sequence[str]) -> None:
    """Write records as CSV (floats to 4 significant digits)."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(columns), lineterminator="\n")
        writer.writeheader()
        for record in records:
            writer.writerow({k: format(v, ".4g") if isinstance(v, float) else v for k, v in record.items()})


PAIRED_COLUMNS = ("n_query", "comparison", "runs", "similarity_diff_mean", "similarity_diff_mean_lo",
                  "similarity_diff_mean_hi", "similarity_diff_median", "similarity_diff_median_lo",
                  "similarity_diff_median_hi", "share_better", "share_equal", "share_worse")


def write_summary(path: Path, summary: Sequence[SummaryRow]) -> None:
    """Write summary.csv (floats to 4 significant digits)."""
    write_csv(path, [row.as_dict() for row in summary], summary_columns())
