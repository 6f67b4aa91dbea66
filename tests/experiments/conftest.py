"""A tiny reference sweep shared by the experiment tests (computed once, in this process)."""

import csv
from pathlib import Path

import pytest

from tableteach.experiments.settings import ExperimentSettings
from tableteach.experiments.sweep import run_sweep

TINY = ExperimentSettings(domain="dinner-random", runs=4, n_query=(0, 2), seed=3)


def rows_without_seconds(folder: Path) -> list[list[str]]:
    """runs.csv without its wall-time column, the one column that is not deterministic."""
    with open(folder / "runs.csv", newline="") as f:
        rows = list(csv.reader(f))
    drop = rows[0].index("seconds")
    return [row[:drop] + row[drop + 1:] for row in rows]


@pytest.fixture(scope="session")
def reference(tmp_path_factory) -> Path:
    """The tiny sweep run in-process (one worker)."""
    out = tmp_path_factory.mktemp("reference")
    run_sweep(TINY, out, workers=1, progress=False)
    return out
