"""A tiny sweep end to end: its files, pairing, prefixes, determinism across workers, resume."""

import csv
import json
import shutil
from dataclasses import replace

import pytest

from tableteach.experiments import executors, sweep
from tableteach.core.session import PROTOCOLS
from tableteach.experiments.simulate import COLUMNS
from tableteach.experiments.summary import summary_columns
from tableteach.experiments.sweep import run_sweep

from .conftest import TINY, rows_without_seconds


def read_dicts(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_writes_every_output_file(reference):
    for name in ("runs.csv", "summary.csv", "paired.csv", "config.json"):
        assert (reference / name).stat().st_size > 0
    for stem in ("by_n_query_median", "by_n_query_mean", "learning_curve"):
        assert (reference / f"{stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert b"<svg" in (reference / f"{stem}.svg").read_bytes()[:1000]
    config = json.loads((reference / "config.json").read_text())
    assert config["settings"] == TINY.to_json()
    assert set(config["versions"]) >= {"tableteach", "numpy", "python"}


def test_runs_csv_has_one_row_per_run_protocol_n_query_and_step(reference):
    with open(reference / "runs.csv", newline="") as f:
        assert next(csv.reader(f)) == list(COLUMNS)
    rows = read_dicts(reference / "runs.csv")
    # per run and protocol: steps 0..2 for n_query 0, steps 0..4 for n_query 2
    assert len(rows) == TINY.runs * len(PROTOCOLS) * (3 + 5)
    keys = {(r["run"], r["protocol"], r["n_query"], r["n_executions"]) for r in rows}
    assert len(keys) == len(rows)
    for r in rows:
        n = int(r["n_executions"])
        assert r["step"] == ("prior" if n == 0 else "demonstration" if n <= 2 or r["protocol"] == "batch" else "query")
        assert 0.0 <= float(r["similarity"]) <= 1.0 and 0.0 <= float(r["map_similarity"]) <= 1.0
        assert float(r["entropy"]) >= 0.0
        assert (r["seed"], r["domain"], r["prior"]) == ("3", "dinner-random", "chains-2020-sat")


def test_protocols_are_paired_and_small_n_query_is_a_prefix(reference):
    rows = read_dicts(reference / "runs.csv")
    metric = ("step", "entropy", "similarity", "map_similarity", "map_formula", "ground_truth")

    def steps(run, protocol, n_query):
        return [tuple(r[c] for c in metric) for r in rows
                if (r["run"], r["protocol"], r["n_query"]) == (str(run), protocol, str(n_query))]

    truths = set()
    for run in range(TINY.runs):
        shared = steps(run, "active", 0)
        assert len(shared) == 3
        for protocol in PROTOCOLS:
            assert steps(run, protocol, 0) == shared  # same truth, same two demonstrations
            assert steps(run, protocol, 2)[:3] == shared  # n_query 0 is a prefix of n_query 2
        truths.add(shared[0][-1])
        assert steps(run, "active", 2) != steps(run, "batch", 2)  # then they part ways
    assert len(truths) > 1  # dinner-random draws a fresh ground truth per run


def test_summary_has_final_step_statistics_per_protocol_and_n_query(reference):
    summary = read_dicts(reference / "summary.csv")
    assert list(summary[0]) == summary_columns()
    assert [(r["protocol"], r["n_query"]) for r in summary] == [(p, n) for p in PROTOCOLS for n in ("0", "2")]
    rows = read_dicts(reference / "runs.csv")
    for s in summary:
        assert s["runs"] == str(TINY.runs)
        final = sorted(float(r["similarity"]) for r in rows if r["protocol"] == s["protocol"]
                       and r["n_query"] == s["n_query"] and int(r["n_executions"]) == 2 + int(s["n_query"]))
        assert float(s["similarity_mean"]) == pytest.approx(sum(final) / len(final), abs=1e-3)
        assert float(s["similarity_median"]) == pytest.approx((final[1] + final[2]) / 2, abs=1e-3)
        for metric in ("similarity", "entropy"):
            for stat in ("median", "mean"):
                low, est, high = (float(s[f"{metric}_{stat}{x}"]) for x in ("_lo", "", "_hi"))
                assert low <= est + 1e-9 and est <= high + 1e-9


def test_same_csvs_with_two_worker_processes(reference, tmp_path):
    result = run_sweep(TINY, tmp_path, workers=2, progress=False)
    assert result.runs_done == TINY.runs
    assert rows_without_seconds(tmp_path) == rows_without_seconds(reference)
    assert (tmp_path / "summary.csv").read_text() == (reference / "summary.csv").read_text()


def test_resume_after_deleting_the_last_runs_rows(reference, tmp_path):
    shutil.copytree(reference, tmp_path, dirs_exist_ok=True)
    lines = (tmp_path / "runs.csv").read_text().splitlines(keepends=True)
    kept = [line for line in lines if not line.startswith(f"{TINY.runs - 1},")]
    kept.append(lines[-1][:25])  # and a half-written line, as a crash mid-write leaves
    (tmp_path / "runs.csv").write_text("".join(kept))
    result = run_sweep(TINY, tmp_path, workers=1, progress=False, figures=False)
    assert (result.runs_skipped, result.runs_done) == (TINY.runs - 1, 1)
    invocations = json.loads((tmp_path / "config.json").read_text())["invocations"]
    assert [(i["runs_computed"], i["runs_resumed"]) for i in invocations] == [(TINY.runs, 0), (1, TINY.runs - 1)]
    assert rows_without_seconds(tmp_path) == rows_without_seconds(reference)
    assert (tmp_path / "summary.csv").read_text() == (reference / "summary.csv").read_text()


def test_resume_after_an_interrupted_sweep(reference, tmp_path, monkeypatch):
    real_inline = executors.inline

    def interrupted(tasks):
        for i, result in enumerate(real_inline(tasks)):
            if i == 2:
                raise KeyboardInterrupt
            yield result

    monkeypatch.setattr(executors, "inline", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(TINY, tmp_path, workers=1, progress=False)
    finished = {r["run"] for r in read_dicts(tmp_path / "runs.csv")}
    assert finished == {"0", "1"}  # what finished before the interruption was kept
    monkeypatch.setattr(executors, "inline", real_inline)
    result = run_sweep(TINY, tmp_path, workers=1, progress=False, figures=False)
    assert (result.runs_skipped, result.runs_done) == (2, 2)
    assert rows_without_seconds(tmp_path) == rows_without_seconds(reference)


def test_rerun_of_a_finished_sweep_computes_nothing(reference, tmp_path):
    shutil.copytree(reference, tmp_path, dirs_exist_ok=True)
    before = (tmp_path / "runs.csv").read_text()
    result = run_sweep(TINY, tmp_path, workers=2, progress=False, figures=False)
    assert result.runs_done == 0
    assert (tmp_path / "runs.csv").read_text() == before


def test_refuses_to_resume_with_different_settings(reference, tmp_path):
    shutil.copytree(reference, tmp_path, dirs_exist_ok=True)
    before = (tmp_path / "runs.csv").read_text()
    with pytest.raises(ValueError, match=r"different settings \(runs: 4 there, 5 now\)"):
        run_sweep(replace(TINY, runs=5), tmp_path, workers=1, progress=False)
    with pytest.raises(ValueError, match="noise: 0.0 there, 0.1 now"):
        run_sweep(replace(TINY, noise=0.1), tmp_path, workers=1, progress=False)
    assert (tmp_path / "runs.csv").read_text() == before


def test_refuses_a_folder_with_rows_but_no_config(tmp_path):
    (tmp_path / "runs.csv").write_text("something else\n")
    with pytest.raises(ValueError, match="config.json does not"):
        run_sweep(TINY, tmp_path, workers=1, progress=False)


def test_a_failing_run_in_a_worker_stops_the_sweep_with_its_message(tmp_path, monkeypatch):
    def bad_task(settings, run):
        return json.dumps({"settings": settings.to_json(), "run": -1})

    monkeypatch.setattr(sweep, "task_json", bad_task)
    with pytest.raises(executors.WorkerError, match=r"run index must be a whole number in \[0, 4\), got -1"):
        run_sweep(TINY, tmp_path, workers=2, progress=False)


def test_paired_differences_match_the_per_protocol_means(reference):
    summary = {(r["protocol"], r["n_query"]): r for r in read_dicts(reference / "summary.csv")}
    paired = read_dicts(reference / "paired.csv")
    assert [(r["n_query"], r["comparison"]) for r in paired] == [
        (n, c) for n in ("0", "2") for c in ("active-batch", "active-random")]
    for r in paired:
        a, b = r["comparison"].split("-")
        expected = (float(summary[(a, r["n_query"])]["similarity_mean"])
                    - float(summary[(b, r["n_query"])]["similarity_mean"]))
        assert float(r["similarity_diff_mean"]) == pytest.approx(expected, abs=2e-3)
        assert sum(float(r[k]) for k in ("share_better", "share_equal", "share_worse")) == pytest.approx(1.0)
        if r["n_query"] == "0":  # no queries yet: every protocol has seen the same two demonstrations
            assert float(r["share_equal"]) == 1.0


def test_a_second_sweep_into_a_busy_folder_is_refused(tmp_path):
    from tableteach.experiments.store import OutputFolder

    holder = OutputFolder(tmp_path, TINY)
    holder.prepare()
    try:
        with pytest.raises(ValueError, match="another sweep is writing to"):
            run_sweep(TINY, tmp_path, workers=1, progress=False)
    finally:
        holder.release()
    assert run_sweep(TINY, tmp_path, workers=1, progress=False, figures=False).runs_done == TINY.runs
