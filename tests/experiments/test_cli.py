"""The `tableteach experiment` command line: a run, and bad settings refused before any work."""

import json

import pytest

from tableteach.cli import main

from .conftest import rows_without_seconds


def run_cli(capsys, *args):
    code = main(["experiment", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_command_runs_a_sweep_and_prints_what_it_did(reference, tmp_path, capsys):
    code, out, _ = run_cli(capsys, "--domain", "dinner-random", "--runs", "4", "--n-query", "0,2", "--seed", "3",
                           "--out", str(tmp_path), "--workers", "1", "--no-progress")
    assert code == 0
    result = json.loads(out)
    assert (result["runs"], result["runs_computed"], result["runs_resumed"]) == (4, 4, 0)
    assert set(result["final_median_similarity"]) == {f"{p}@{n}" for p in ("active", "random", "batch")
                                                       for n in (0, 2)}
    assert rows_without_seconds(tmp_path) == rows_without_seconds(reference)


@pytest.mark.parametrize("args, message", [
    (["--domain", "kitchen"], "invalid choice: 'kitchen'"),
    (["--domain", "synthetic", "--n-query", "-1"], "must be >= 0, got -1"),
    (["--domain", "synthetic", "--n-query", "two"], "'two' is not a whole number"),
    (["--domain", "synthetic", "--runs", "0"], "runs must be a whole number >= 1, got 0"),
    (["--domain", "synthetic", "--noise", "1.5"], "noise must be a probability in [0, 1], got 1.5"),
    (["--domain", "synthetic", "--workers", "0"], "workers must be a whole number >= 1, got 0"),
    (["--domain", "dinner-task1", "--truth-sampler", "authors"], "ground truth is fixed"),
    (["--domain", "synthetic", "--prior", "uniform"], "invalid choice: 'uniform'"),
    (["--domain", "synthetic", "--learner-flip-rate", "0.5"], "learner_flip_rate must be a probability in [0, 0.5)"),
    (["--domain", "synthetic", "--flip-rate", "-0.1"], "learner_flip_rate must be a probability in [0, 0.5)"),
    (["--domain", "synthetic", "--active-strategy", "entropy"], "invalid choice: 'entropy'"),
])
def test_bad_settings_are_one_line_errors_before_any_work(tmp_path, capsys, args, message):
    out = tmp_path / "sweep"
    code, stdout, err = run_cli(capsys, *args, "--runs" if "--runs" not in args else "--seed", "2",
                                "--out", str(out), "--no-progress")
    assert code == 2
    assert stdout == ""
    assert err.count("\n") == 1 and message in err
    assert not out.exists()


def test_unwritable_output_folder_is_refused(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    code, _, err = run_cli(capsys, "--domain", "synthetic", "--runs", "2", "--out", str(blocker / "sweep"),
                           "--no-progress")
    assert code == 2
    assert "cannot create output folder" in err and "expected a folder you can write to" in err
