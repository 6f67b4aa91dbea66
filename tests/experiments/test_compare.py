"""Cross-sweep figures and tables: the user study in simulation and the fallible teacher."""

import csv

import pytest

import numpy as np

from tableteach.experiments.compare import STUDY_TASKS, main
from tableteach.experiments.summary import weighted_bootstrap_ci, weighted_statistic
from tableteach.experiments.settings import ExperimentSettings
from tableteach.experiments.sweep import run_sweep


def sweep(tmp_path, name, **kwargs):
    settings = ExperimentSettings(runs=3, n_query=(3,), test_success=True, **kwargs)
    run_sweep(settings, tmp_path / name, workers=1, progress=False, figures=False)
    return tmp_path / name


def read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_user_study_curves_cover_both_tasks_from_the_last_demonstration(tmp_path):
    task1 = sweep(tmp_path, "t1", domain="dinner-task1", truth_sampler="fixed")
    task2 = sweep(tmp_path, "t2", domain="dinner-task2", truth_sampler="fixed")
    assert main(["user-study", "--task1", str(task1), "--task2", str(task2), "--out", str(tmp_path / "study")]) == 0
    rows = read(tmp_path / "study" / "user_study.csv")
    assert {(r["task"], r["protocol"]) for r in rows} == {(t, p) for t in STUDY_TASKS
                                                          for p in ("active", "random", "batch")}
    assert sorted({int(r["n_executions"]) for r in rows}) == [2, 3, 4, 5]
    both = {int(r["n_executions"]): r for r in rows if r["task"] == "both" and r["protocol"] == "active"}
    assert all(int(r["runs"]) == 6 for r in both.values())  # the two tasks pooled
    final = {(r["task"], r["protocol"]): float(r["similarity_median"]) for r in rows if r["n_executions"] == "5"}
    finals = [[float(r["similarity"]) for r in read(folder / "runs.csv")
               if r["protocol"] == "active" and r["n_executions"] == "5"] for folder in (task1, task2)]
    expanded = sorted(finals[0] * 7 + finals[1] * 2)  # 3 runs each: 21:6 is 7 copies of a Task 1 run to 2
    assert final[("both-paper", "active")] == pytest.approx(expanded[13], abs=1e-4)  # the 14th of 27
    for r in rows:
        assert float(r["similarity_median_lo"]) <= float(r["similarity_median"]) <= float(r["similarity_median_hi"])
    assert (tmp_path / "study" / "user_study.png").read_bytes()[:4] == b"\x89PNG"


def test_noise_table_has_one_row_per_level_and_protocol(tmp_path):
    folders = [sweep(tmp_path, f"n{noise}", domain="dinner-task2", truth_sampler="fixed", noise=noise)
               for noise in (0.0, 0.5)]
    assert main(["noise", *map(str, folders), "--n-query", "3", "--out", str(tmp_path / "noise")]) == 0
    rows = read(tmp_path / "noise" / "noise.csv")
    assert {(float(r["noise"]), r["protocol"]) for r in rows} == {(n, p) for n in (0.0, 0.5)
                                                                  for p in ("active", "random", "batch")}
    assert all(0.0 <= float(r["test_success_mean"]) <= 1.0 for r in rows)
    assert (tmp_path / "noise" / "noise.png").exists()


def test_compare_refuses_what_it_cannot_use(tmp_path, capsys):
    untested = tmp_path / "plain"
    run_sweep(ExperimentSettings(domain="dinner-task2", truth_sampler="fixed", runs=2, n_query=(1,)), untested,
              workers=1, progress=False, figures=False)
    assert main(["noise", str(untested), "--n-query", "1", "--out", str(tmp_path / "o")]) == 2
    assert "did not measure test success; expected a sweep run with --test-success" in capsys.readouterr().err
    assert main(["noise", str(untested), "--n-query", "4", "--out", str(tmp_path / "o")]) == 2
    assert "has no rows for n_query 4" in capsys.readouterr().err
    assert main(["user-study", "--task1", str(tmp_path / "nope"), "--task2", str(untested),
                 "--out", str(tmp_path / "o")]) == 2
    assert "is not a finished sweep folder" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["noise"], ["user-study", "--task1", "x"]])
def test_compare_needs_its_arguments(argv):
    with pytest.raises(SystemExit):
        main(argv)


def test_noise_table_puts_the_noise_aware_learner_beside_the_authors(tmp_path):
    folders = [sweep(tmp_path, "plain", domain="dinner-random", noise=0.2),
               sweep(tmp_path, "aware", domain="dinner-random", noise=0.2, learner_flip_rate=0.2)]
    assert main(["noise", *map(str, folders), "--n-query", "3", "--out", str(tmp_path / "noise")]) == 0
    rows = read(tmp_path / "noise" / "noise.csv")
    assert {(r["learner"], r["protocol"]) for r in rows} == {(learner, p) for learner in ("authors", "noise-aware")
                                                             for p in ("active", "random", "batch")}
    batch = {r["learner"]: r["similarity_median"] for r in rows if r["protocol"] == "batch"}
    assert batch["authors"] == batch["noise-aware"]  # Batch sees no verdicts, so the learners agree on it


def test_paired_sweeps_subtract_run_by_run(tmp_path):
    base = sweep(tmp_path, "base", domain="dinner-random")
    eig = sweep(tmp_path, "eig", domain="dinner-random", active_strategy="information-gain")
    assert main(["paired", str(base), str(eig), "--label", "EIG - US", "--out", str(tmp_path / "p")]) == 0
    rows = {r["protocol"]: r for r in read(tmp_path / "p" / "paired_sweeps.csv")}
    assert set(rows) == {"active", "random", "batch"}
    for protocol in ("random", "batch"):  # only Active's queries changed
        assert float(rows[protocol]["diff_mean"]) == 0.0 and float(rows[protocol]["share_equal"]) == 1.0
    finals = {}
    for name in ("base", "eig"):
        finals[name] = sorted((int(r["run"]), float(r["similarity"])) for r in read(tmp_path / name / "runs.csv")
                              if r["protocol"] == "active" and r["n_executions"] == "5")
    diffs = [b[1] - a[1] for a, b in zip(finals["base"], finals["eig"], strict=True)]
    assert float(rows["active"]["diff_mean"]) == pytest.approx(sum(diffs) / len(diffs), abs=1e-3)
    assert (tmp_path / "p" / "paired_sweeps.svg").exists()


def test_paired_sweeps_refuse_sweeps_of_other_runs(tmp_path, capsys):
    a = sweep(tmp_path, "a", domain="dinner-random")
    b = sweep(tmp_path, "b", domain="dinner-random", seed=1)
    assert main(["paired", str(a), str(b), "--out", str(tmp_path / "p")]) == 2
    assert "do not share their runs (seed: 0 vs 1)" in capsys.readouterr().err


def test_weighted_pooling_gives_each_group_its_share_whatever_its_size():
    low, high = np.zeros(200), np.ones(10)
    assert weighted_statistic([low, high], [21, 6], "median") == 0.0
    assert weighted_statistic([low, high], [6, 21], "median") == 1.0
    assert weighted_statistic([low, high], [21, 6], "mean") == pytest.approx(6 / 27)
    est, lo, hi = weighted_bootstrap_ci([np.arange(100.0), np.arange(100.0) + 1000], [3, 1], "median",
                                        np.random.default_rng(0), n_resamples=200)
    assert lo <= est <= hi and est == pytest.approx(66, abs=1)  # the 2/3 point of the first group


def test_sizes_put_each_size_beside_the_others(tmp_path, capsys):
    """Two synthetic sweeps of different sizes: one row per size, comparison and n_query, from their paired.csv."""
    small = sweep(tmp_path, "small", domain="synthetic", n_waypoints=3, n_threats=2)
    large = sweep(tmp_path, "large", domain="synthetic", n_waypoints=4, n_threats=2)
    assert main(["sizes", str(small), str(large), "--out", str(tmp_path / "s")]) == 0
    rows = read(tmp_path / "s" / "sizes.csv")
    assert {(r["waypoints"], r["comparison"]) for r in rows} == {
        (w, c) for w in ("3", "4") for c in ("active-batch", "active-random")}
    paired = {r["comparison"]: r for r in read(large / "paired.csv")}
    mine = next(r for r in rows if r["waypoints"] == "4" and r["comparison"] == "active-random")
    assert mine["similarity_diff_mean"] == paired["active-random"]["similarity_diff_mean"]
    assert (tmp_path / "s" / "sizes.png").exists() and (tmp_path / "s" / "sizes.svg").exists()
    dinner = sweep(tmp_path, "dinner", domain="dinner-random")
    assert main(["sizes", str(small), str(dinner), "--out", str(tmp_path / "o")]) == 2
    assert "expected synthetic sweeps" in capsys.readouterr().err
