"""Power from simulation: how many participants a study needs to detect a protocol contrast.

A pool of simulated runs (one sweep: each run a simulated participant whose two protocols share the
truth and the first demonstrations) gives each run's paired difference of final similarity. For a
sample size n, many studies of n participants are drawn from the pool with replacement, and each is
tested with a two-sided sign-flip permutation test of the mean paired difference at level alpha; the
power is the share of studies that reject "no difference". The teacher model is given (demonstration
mode, flip rate) or fitted from a pilot's export (experiments/pilot_teacher.py).
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from tqdm import tqdm

from .settings import ExperimentSettings
from .summary import final_values

CONTRASTS = {"active-batch": ("active", "batch"), "active-random": ("active", "random"),
             "random-batch": ("random", "batch")}
N_FLIPS = 2000
POWER_COLUMNS = ("contrast", "participants", "studies", "alpha", "power", "power_lo", "power_hi",
                 "mean_difference", "pool_runs", "teacher_flip_rate", "demo_mode", "domain", "n_query")


def parse_sizes(text: str) -> tuple[int, ...]:
    """'10,20,40' as sorted distinct sample sizes >= 2; ValueError names a bad one."""
    try:
        sizes = sorted({int(part) for part in text.split(",")})
    except ValueError:
        raise ValueError(f"--participants {text!r}: expected whole numbers separated by commas, e.g. 10,20,40"
                         ) from None
    if not sizes or sizes[0] < 2:
        raise ValueError(f"--participants {text!r}: a study needs at least 2 participants")
    return tuple(sizes)


def pool_differences(rows: Sequence[dict[str, str]], settings: ExperimentSettings, contrast: str) -> np.ndarray:
    """Each run's paired difference of final similarity (first protocol minus second) at the largest n_query."""
    a, b = CONTRASTS[contrast]
    values = final_values(rows, settings)
    n_query = settings.max_n_query
    return values[(a, n_query)]["similarity"] - values[(b, n_query)]["similarity"]


def sign_flip_p_values(samples: np.ndarray, rng: np.random.Generator, n_flips: int = N_FLIPS) -> np.ndarray:
    """Two-sided permutation p-value of the mean of each row of samples (studies x participants)."""
    observed = np.abs(samples.mean(axis=1))
    signs = rng.choice(np.array([-1.0, 1.0]), size=(n_flips, samples.shape[1]))
    null = np.abs(samples @ signs.T) / samples.shape[1]  # studies x flips
    return ((null >= observed[:, None] - 1e-12).sum(axis=1) + 1) / (n_flips + 1)


def power_table(diffs: np.ndarray, sizes: Sequence[int], studies: int, alpha: float, seed: int,
                progress: bool = True) -> list[dict[str, Any]]:
    """Per sample size: power (with a 95% Wilson interval over the simulated studies) and the mean difference."""
    out = []
    for n in tqdm(sizes, unit="size", desc="power", file=sys.stderr, disable=not progress):
        rng = np.random.default_rng([seed, 5, n])
        samples = diffs[rng.integers(0, diffs.size, size=(studies, n))]
        rejected = sign_flip_p_values(samples, rng) <= alpha
        k = float(rejected.sum())
        z = 1.96
        centre = (k + z * z / 2) / (studies + z * z)
        half = z * np.sqrt(k * (studies - k) / studies + z * z / 4) / (studies + z * z)
        out.append({"participants": n, "studies": studies, "alpha": alpha, "power": k / studies,
                    "power_lo": max(0.0, centre - half), "power_hi": min(1.0, centre + half),
                    "mean_difference": float(diffs.mean())})
    return out


def plot_power(table: Sequence[dict[str, Any]], title: str, stem: Path) -> list[Path]:
    """Power against the number of participants, with the conventional 0.8 line."""
    from .figures import _save, plt

    fig, ax = plt.subplots(figsize=(5.5, 4), constrained_layout=True)
    x = np.array([r["participants"] for r in table], dtype=float)
    y = np.array([r["power"] for r in table])
    err = [y - np.array([r["power_lo"] for r in table]), np.array([r["power_hi"] for r in table]) - y]
    ax.errorbar(x, y, yerr=err, marker="o", capsize=3, color="#1b6ca8")
    ax.axhline(0.8, color="grey", linestyle="--", linewidth=0.8)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("participants (paired: each does both protocols' data)")
    ax.set_ylabel("power at alpha 0.05 (95% CI)")
    ax.grid(alpha=0.3)
    fig.suptitle(textwrap.fill(title, 75), fontsize=9)
    return _save(fig, stem)
