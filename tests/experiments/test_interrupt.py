"""A real interruption: Ctrl-C a running sweep with worker processes, then resume it."""

import signal
import subprocess
import sys

from tableteach.experiments.settings import ExperimentSettings
from tableteach.experiments.sweep import run_sweep

from tests.waiting import wait_until

from .conftest import rows_without_seconds

SETTINGS = ExperimentSettings(domain="dinner-random", runs=40, n_query=(0,), seed=11)
ARGS = ["--domain", "dinner-random", "--runs", "40", "--n-query", "0", "--seed", "11", "--no-progress"]


def test_ctrl_c_keeps_finished_runs_and_the_rerun_completes_the_sweep(tmp_path):
    out = tmp_path / "interrupted"
    proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "experiment", *ARGS, "--out", str(out),
                             "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    runs_csv = out / "runs.csv"
    wait_until(lambda: runs_csv.exists() and runs_csv.read_text().count("\n") > 1 + 9,
               "the sweep to store ten runs", timeout=120, interval=0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err
    kept = {line.split(",")[0] for line in runs_csv.read_text().splitlines()[1:]}
    assert 0 < len(kept) < SETTINGS.runs

    resumed = run_sweep(SETTINGS, out, workers=1, progress=False, figures=False)
    assert resumed.runs_skipped >= 1 and resumed.runs_skipped + resumed.runs_done == SETTINGS.runs
    fresh = tmp_path / "fresh"
    run_sweep(SETTINGS, fresh, workers=1, progress=False, figures=False)
    assert rows_without_seconds(out) == rows_without_seconds(fresh)
