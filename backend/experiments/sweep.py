"""A whole sweep: check settings, skip finished runs, run the rest, then summarise and plot."""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from tqdm import tqdm

from . import executors
from .settings import ExperimentSettings
from .simulate import task_json
from .store import OutputFolder
from .summary import PAIRED_COLUMNS, SummaryRow, paired_differences, summarize, write_csv, write_summary

SUMMARY = "summary.csv"
PAIRED = "paired.csv"


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did and where it wrote it."""

    out: Path
    runs_total: int
    runs_skipped: int
    runs_done: int
    seconds: float
    summary: list[SummaryRow]


def default_workers() -> int:
    """All local cores."""
    return os.cpu_count() or 1


def run_sweep(
    settings: ExperimentSettings,
    out: Path | str,
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    progress: bool = True,
    figures: bool = True,
) -> SweepResult:
    """Run (or resume) a sweep into ``out``; every setting is checked before any run starts."""
    workers = default_workers() if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a whole number >= 1, got {workers!r}")
    if dask_address is not None:
        executors.check_dask(dask_address)
    started = time.perf_counter()
    folder = OutputFolder(Path(out), settings)
    done = folder.prepare()
    try:
        todo = [run for run in range(settings.runs) if run not in done]
        with tqdm(total=settings.runs, initial=len(done), unit="run", desc="runs", file=sys.stderr,
                  disable=not progress, dynamic_ncols=True) as bar:
            for result in _results(settings, todo, workers, dask_address):
                data = json.loads(result)
                folder.append(data["rows"])
                bar.update(1)

        folder.finish()
        rows = folder.read_rows()
        summary = summarize(rows, settings)
        write_summary(folder.path / SUMMARY, summary)
        write_csv(folder.path / PAIRED, paired_differences(rows, settings), PAIRED_COLUMNS)
        if figures:
            from .figures import write_figures  # matplotlib is imported only when plotting

            write_figures(summary, rows, settings, folder.path)
        seconds = time.perf_counter() - started
        folder.record_invocation({"workers": None if dask_address else workers, "dask": dask_address,
                                  "runs_computed": len(todo), "runs_resumed": len(done),
                                  "wall_seconds": round(seconds, 1)})
    finally:
        folder.release()
    return SweepResult(folder.path, settings.runs, len(done), len(todo), seconds, summary)


def _results(settings: ExperimentSettings, todo: list[int], workers: int, dask_address: str | None) -> Iterator[str]:
    tasks = [task_json(settings, run) for run in todo]
    if not tasks:
        return iter(())
    if dask_address is not None:
        return executors.dask_cluster(tasks, dask_address)
    if workers == 1:
        return executors.inline(tasks)
    return executors.local_pool(tasks, workers)
