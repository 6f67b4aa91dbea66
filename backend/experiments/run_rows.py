"""runs.csv rows of one run's protocol: shared by the enumerating simulation (simulate.py) and the exact one
(exact_run.py)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .settings import ExperimentSettings


def protocol_rows(settings: ExperimentSettings, run: int, protocol: str, truth_text: str,
                  steps: Sequence[Any]) -> list[list]:
    """runs.csv rows of one protocol's learning steps: for each n_query, the prefix of steps it covers."""
    rows: list[list] = []
    for n_query in settings.n_query:
        for n_executions, step in enumerate(steps[: settings.n_demonstrations + n_query + 1]):
            rows.append([
                run, settings.seed, settings.domain, settings.prior, protocol, n_query, step.kind,
                n_executions, step.entropy, step.similarity, step.map_similarity, step.map_formula,
                truth_text, "" if step.test_success is None else step.test_success, step.seconds,
            ])
    return rows
