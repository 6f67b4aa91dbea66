"""Power from simulation: the permutation test, the power table and the command's errors."""

import json

import numpy as np
import pytest

from tableteach.cli import main
from tableteach.experiments.power import parse_sizes, power_table, sign_flip_p_values


def test_sign_flip_test_rejects_a_clear_shift_and_not_noise_around_zero():
    rng = np.random.default_rng(0)
    shifted = rng.normal(0.5, 0.2, size=(200, 20))
    centred = rng.normal(0.0, 0.2, size=(400, 20))
    assert (sign_flip_p_values(shifted, rng) <= 0.05).mean() > 0.99
    assert (sign_flip_p_values(centred, rng) <= 0.05).mean() == pytest.approx(0.05, abs=0.035)


def test_power_grows_with_the_number_of_participants():
    diffs = np.random.default_rng(1).normal(0.05, 0.2, size=300)
    table = power_table(diffs, [5, 20, 80], 300, 0.05, seed=0, progress=False)
    powers = [r["power"] for r in table]
    assert powers[0] < powers[1] < powers[2]
    assert all(r["power_lo"] <= r["power"] <= r["power_hi"] for r in table)


def test_the_command_writes_a_table_and_a_figure(tmp_path, capsys):
    code = main(["power", "--runs", "4", "--participants", "3,6", "--studies", "20", "--domain", "dinner-task2",
                 "--workers", "1", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result["power"]) == {"3", "6"}
    assert (tmp_path / "power.csv").read_text().startswith("contrast,participants,")
    assert (tmp_path / "power.svg").exists() and (tmp_path / "power.png").exists()


@pytest.mark.parametrize("args, message", [
    (["--participants", "1,10"], "a study needs at least 2 participants"),
    (["--participants", "ten"], "expected whole numbers separated by commas"),
    (["--flip-rate", "0.5"], "--flip-rate must be a probability in [0, 0.5)"),
    (["--contrast", "active-nothing"], "invalid choice: 'active-nothing'"),
    (["--pilot", "nowhere.zip"], "is neither a folder nor a zip file"),
    (["--pilot", "nowhere.zip", "--flip-rate", "0.1"], "(--flip-rate) or a pilot to fit it from (--pilot), not both"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert parse_sizes("20,10,10") == (10, 20)
    code = main(["power", *args, "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
