"""The Dask path: the same sweep on a (local, in-process) Dask cluster gives the same CSVs."""

import pytest

distributed = pytest.importorskip("distributed")

from tableteach.experiments.sweep import run_sweep  # noqa: E402

from .conftest import TINY, rows_without_seconds  # noqa: E402


def test_sweep_on_a_dask_cluster_matches_the_local_run(reference, tmp_path):
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        result = run_sweep(TINY, tmp_path, dask_address=cluster.scheduler_address, progress=False)
    assert result.runs_done == TINY.runs
    assert rows_without_seconds(tmp_path) == rows_without_seconds(reference)
    assert (tmp_path / "summary.csv").read_text() == (reference / "summary.csv").read_text()
