"""The simulation that validates the consistency score: its files, the flag rates, and its refusals."""

import csv

import pytest

from tableteach.core.consistency import FLAG_BELOW
from tableteach.experiments.teacher_consistency import main


def test_it_writes_scores_auc_flags_and_the_roc(tmp_path, capsys):
    assert main(["--runs", "3", "--flip", "0.4", "--out", str(tmp_path), "--no-progress"]) == 0
    assert "AUC" in capsys.readouterr().out
    with open(tmp_path / "consistency_scores.csv", newline="") as f:
        scores = list(csv.DictReader(f))
    with open(tmp_path / "consistency_flags.csv", newline="") as f:
        flags = {r["teacher_flip_rate"]: r for r in csv.DictReader(f)}
    assert len(scores) == 6 and set(flags) == {"0.0", "0.4"}
    for rate, row in flags.items():
        lowest = [float(r["lowest_p_verdict"]) for r in scores if r["teacher_flip_rate"] == rate]
        assert int(row["teachers"]) == 3 and float(row["flag_below"]) == FLAG_BELOW
        assert int(row["flagged"]) == sum(p < FLAG_BELOW for p in lowest)
    assert (tmp_path / "consistency_roc.png").exists() and (tmp_path / "consistency_roc.svg").exists()


@pytest.mark.parametrize("args, message", [
    (["--flip", "0.5"], "--flip must be a probability in [0, 0.5)"),
    (["--flip", "0"], "--flip must be above 0"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert main([*args, "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
