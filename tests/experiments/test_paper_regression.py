"""Regression: with the authors' demonstrator (the default), Active beats Batch as the paper found."""

import numpy as np

from tableteach.experiments.settings import ExperimentSettings
from tableteach.experiments.simulate import COLUMNS, simulate_run

COL = {c: i for i, c in enumerate(COLUMNS)}


def test_active_beats_batch_at_four_queries_with_the_default_demonstrator():
    settings = ExperimentSettings(domain="synthetic", runs=60, n_query=(4,), seed=0)
    assert settings.demo_mode == "required-only"
    final = settings.n_demonstrations + 4
    diffs = []
    for run in range(settings.runs):
        rows = simulate_run(settings, run)
        last = {r[COL["protocol"]]: r[COL["similarity"]] for r in rows if r[COL["n_executions"]] == final}
        diffs.append(last["active"] - last["batch"])
    assert np.median(diffs) > 0  # the paired Active - Batch median similarity difference
