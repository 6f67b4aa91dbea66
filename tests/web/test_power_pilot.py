"""tableteach power --pilot end to end: scripted teachers complete a pilot in-process, its exports.zip fits the
teacher's flip rate, and the power command simulates its pool with that teacher."""

from __future__ import annotations

import csv
import io
import json
import zipfile
from pathlib import Path
from typing import Any

import pytest

from tableteach.cli import main
from tableteach.client import ParticipantClient, run_teacher
from tableteach.experiments.pilot_teacher import fitted_demo_mode
from tableteach.services import TASK_FORMULAS

from .helpers import EXP, make_study

N_QUERIES = 3
# three perfect teachers and one who flips every verdict: a quarter of the query verdicts contradict the truth
PILOT = ((0, 0.0), (1, 0.0), (2, 0.0), (3, 1.0))


def export_of(client: Any, conditions: list[str], teachers: tuple[tuple[int, float], ...], path: Path,
              task: str = "task1", demo_mode: str = "required-only") -> Path:
    """A study of these conditions on one task completed by the teachers; its exports.zip (pilots included)."""
    study_id = make_study(client, conditions, tasks=[{"key": task}], n_queries=N_QUERIES, pilot=True)
    for seed, noise in teachers:
        api = ParticipantClient("http://testserver")
        api.http = client
        run = run_teacher("http://testserver", study_id, [TASK_FORMULAS[task]], noise=noise, seed=seed,
                          demo_mode=demo_mode, client=api, poll_seconds=0.0, timeout=120)
        assert run.completion_code
    response = client.get(f"/api/v1/studies/{study_id}/exports/exports.zip?include_pilot=true", headers=EXP)
    assert response.status_code == 200, response.text
    path.write_bytes(response.content)
    return path


@pytest.fixture(scope="module")
def pilots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """An Active pilot (the teachers above), a Batch-only one (no query verdicts), and two Active pilots on Task 2
    whose teachers demonstrate as the authors' demonstrator does (only what is required) or optimally (also the
    optional knife and fork, in any order the task allows)."""
    from .conftest import in_process_app

    tmp = tmp_path_factory.mktemp("pilot")
    with in_process_app(tmp) as client:
        return {"active": export_of(client, ["active"], PILOT, tmp / "active.zip"),
                "batch": export_of(client, ["batch"], ((0, 0.0),), tmp / "batch.zip"),
                **{mode: export_of(client, ["active"], ((0, 0.0), (1, 0.0), (2, 0.0)), tmp / f"{mode}.zip", "task2",
                                   mode) for mode in ("required-only", "optimal")}}


def power(args: list[str], out: Path) -> list[str]:
    return ["power", *args, "--runs", "4", "--participants", "3,6", "--studies", "20", "--domain", "dinner-task2",
            "--workers", "1", "--out", str(out), "--no-progress"]


def test_the_pilot_fits_the_flip_rate_and_the_pool_is_simulated_with_it(pilots: dict[str, Path], tmp_path: Path,
                                                                        capsys) -> None:
    with zipfile.ZipFile(pilots["active"]) as archive:
        beliefs = list(csv.DictReader(io.StringIO(archive.read("beliefs.csv").decode())))
    assert sum(r["record_kind"] == "query" for r in beliefs) == len(PILOT) * N_QUERIES
    out = tmp_path / "power"
    assert main(power(["--pilot", str(pilots["active"])], out)) == 0, capsys.readouterr().err
    result = json.loads(capsys.readouterr().out)
    assert result["teacher_flip_rate"] == 0.25
    fitted = result["fitted_from"]
    assert (fitted["pilot"], fitted["query_verdicts"]) == ("active.zip", len(PILOT) * N_QUERIES)
    assert fitted["demonstrations"] == sum(r["record_kind"] == "demonstration" for r in beliefs) > 0
    assert result["demo_mode"] == "required-only"  # the scripted teachers demonstrate as the authors' did
    assert json.loads((out / "pool" / "config.json").read_text())["settings"]["noise"] == 0.25
    with open(out / "power.csv", newline="", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    assert [r["participants"] for r in table] == ["3", "6"]
    assert {r["teacher_flip_rate"] for r in table} == {"0.25"}
    assert all(0.0 <= float(r["power"]) <= 1.0 for r in table)
    assert (out / "power.png").stat().st_size > 1000 and (out / "power.svg").stat().st_size > 1000


def another_version(export: Path, path: Path) -> Path:
    """The export with beliefs.csv lacking its trace column, as another version might write it."""
    with zipfile.ZipFile(export) as src, zipfile.ZipFile(path, "w") as dst:
        for name in src.namelist():
            text = src.read(name).decode()
            if name == "beliefs.csv":
                rows = list(csv.DictReader(io.StringIO(text)))
                buffer = io.StringIO()
                writer = csv.DictWriter(buffer, [c for c in rows[0] if c != "trace"], extrasaction="ignore")
                writer.writeheader()
                writer.writerows(rows)
                text = buffer.getvalue()
            dst.writestr(name, text)
    return path


@pytest.mark.parametrize("case, message", [
    ("batch", "has no query verdicts on a task with a ground truth"),
    ("version", "is an export from another version (beliefs.csv lacks the columns trace)"),
])
def test_a_pilot_that_cannot_be_fitted_is_one_line_and_exit_2(pilots: dict[str, Path], tmp_path: Path, capsys,
                                                               case: str, message: str) -> None:
    export = pilots["batch"] if case == "batch" else another_version(pilots["active"], tmp_path / "old.zip")
    out = tmp_path / "power"
    assert main(power(["--pilot", str(export)], out)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not (out / "pool").exists()  # refused before simulating anything


@pytest.mark.parametrize("mode", ["required-only", "optimal"])
def test_the_pilot_fits_how_its_teachers_demonstrate(pilots: dict[str, Path], mode: str) -> None:
    fit = fitted_demo_mode(pilots[mode])
    with zipfile.ZipFile(pilots[mode]) as archive:
        beliefs = list(csv.DictReader(io.StringIO(archive.read("beliefs.csv").decode())))
    assert fit.demonstrations == sum(r["record_kind"] == "demonstration" for r in beliefs) >= 6  # two per teacher
    assert fit.mode == mode, fit
    other = "optimal" if mode == "required-only" else "required-only"
    assert fit.log_likelihood[mode] > fit.log_likelihood[other] + 5  # not a near tie


def test_a_demonstration_mode_given_beside_a_pilot_wins_over_the_fitted_one(pilots: dict[str, Path], tmp_path: Path,
                                                                             capsys) -> None:
    out = tmp_path / "power"
    assert main(power(["--pilot", str(pilots["optimal"]), "--demo-mode", "uniform"], out)) == 0
    assert json.loads(capsys.readouterr().out)["demo_mode"] == "uniform"
    assert json.loads((out / "pool" / "config.json").read_text())["settings"]["demo_mode"] == "uniform"
