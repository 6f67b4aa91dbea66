"""tableteach replay on a real export: scripted teachers complete a study in-process, its exports.zip is
replayed; the study's own settings reproduce beliefs.csv, other learners differ where they should."""

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
from tableteach.services import TASK_FORMULAS

from .helpers import EXP, make_study


@pytest.fixture(scope="module")
def export_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """exports.zip of a study that three scripted teachers (one of them fallible) completed."""
    from .conftest import in_process_app

    tmp = tmp_path_factory.mktemp("study")
    with in_process_app(tmp) as client:
        study_id = make_study(client, ["active", "batch"])
        for seed, noise in ((0, 0.0), (1, 0.0), (2, 0.5)):
            api = ParticipantClient("http://testserver")
            api.http = client  # the in-process app speaks the same HTTP
            run = run_teacher("http://testserver", study_id, [TASK_FORMULAS["task1"]], noise=noise, seed=seed,
                              client=api, poll_seconds=0.0, timeout=120)
            assert run.completion_code
        response = client.get(f"/api/v1/studies/{study_id}/exports/exports.zip", headers=EXP)
        assert response.status_code == 200, response.text
    path = tmp / "exports.zip"
    path.write_bytes(response.content)
    return path


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_replaying_with_the_study_settings_reproduces_beliefs_csv(export_zip: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "replay"
    code = main(["replay", str(export_zip), "--learner", "study", "--learner", "flip=0.2", "--learner",
                 "data=demonstrations", "--out", str(out), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    result = json.loads(capsys.readouterr().out)
    assert result["sessions"] == 3 and result["learners"] == ["study", "flip=0.2", "data=demonstrations"]
    with zipfile.ZipFile(export_zip) as archive:
        beliefs = list(csv.DictReader(io.StringIO(archive.read("beliefs.csv").decode())))
    rows = read_csv(out / "replay.csv")
    assert len(rows) == 3 * len(beliefs)
    study = {(r["participant_id"], r["step"]): r for r in rows if r["learner"] == "study"}
    assert len(study) == len(beliefs)
    for b in beliefs:
        r = study[(b["participant_id"], b["step"])]
        assert abs(float(r["similarity"]) - float(b["similarity"])) < 1e-9
        assert abs(float(r["entropy"]) - float(b["entropy"])) < 1e-9
        assert r["map_formula"] == b["map_formula"] == r["study_map_formula"]
    # The demonstrations-only learner does not move at a query step; the noise-aware one differs after a
    # verdict the fallible teacher gave.
    by = {(r["learner"], r["participant_id"], int(r["step"])): r for r in rows}
    queries = [b for b in beliefs if b["record_kind"] == "query"]
    assert queries
    for b in queries:
        step = int(b["step"])
        assert by[("data=demonstrations", b["participant_id"], step)]["entropy"] == \
            by[("data=demonstrations", b["participant_id"], step - 1)]["entropy"]
    assert any(abs(float(by[("flip=0.2", b["participant_id"], int(b["step"]))]["entropy"]) - float(b["entropy"]))
               > 1e-6 for b in queries)
    for suffix in (".png", ".svg"):
        assert (out / f"replay{suffix}").stat().st_size > 1000


def test_an_unpacked_export_folder_replays_the_same(export_zip: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "unpacked"
    with zipfile.ZipFile(export_zip) as archive:
        archive.extractall(folder)
    assert main(["replay", str(folder), "--learner", "study", "--out", str(tmp_path / "a"), "--no-progress"]) == 0
    assert main(["replay", str(export_zip), "--learner", "study", "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    assert (tmp_path / "a" / "replay.csv").read_text() == (tmp_path / "b" / "replay.csv").read_text()


def old_export(tmp_path: Path, export_zip: Path) -> Path:
    """The same export with beliefs.csv lacking its trace column, as another version might write it."""
    path = tmp_path / "old.zip"
    with zipfile.ZipFile(export_zip) as src, zipfile.ZipFile(path, "w") as dst:
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
    ("learner", "unknown learner 'flips=0.1'"),
    ("flip", "flip must be a probability in [0, 0.5), got 0.5"),
    ("prior", "unknown learner 'prior=flat': prior 'flat'"),
    ("version", "is an export from another version (beliefs.csv lacks the columns trace)"),
    ("missing", "is neither a folder nor a zip file"),
])
def test_bad_input_is_one_line_and_exit_2(export_zip: Path, tmp_path: Path, capsys, case: str, message: str) -> None:
    export: Any = {"version": old_export(tmp_path, export_zip), "missing": tmp_path / "nope.txt"}.get(case, export_zip)
    learner = {"learner": "flips=0.1", "flip": "flip=0.5", "prior": "prior=flat"}.get(case, "study")
    if case == "missing":
        export.write_text("not an export")
    out = tmp_path / "out"
    code = main(["replay", str(export), "--learner", learner, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert not (out / "replay.csv").exists()


def test_the_export_gives_each_verdict_its_probability_and_each_participant_a_score(export_zip: Path) -> None:
    from tableteach.core.session import belief_after
    from tableteach.experiments.replay import _verdicts, read_export, sessions

    export = read_export(export_zip)
    probabilities = []
    for rows in sessions(export).values():
        data = _verdicts(rows)
        for row in rows:
            step = int(row["step"])
            if row["record_kind"] != "query":
                assert row["p_verdict"] == ""
                continue
            trace, acceptable, _ = data[step - 1]
            p = belief_after("dinner", export.study["prior"], tuple((t, a) for t, a, _ in data[:step - 1])
                             ).p_acceptable(trace)
            assert float(row["p_verdict"]) == pytest.approx(p if acceptable else 1 - p, abs=1e-12)
            probabilities.append(float(row["p_verdict"]))
        scores = {row["consistency_score"] for row in rows}
        assert len(scores) == 1  # one score per participant and task, on every row
        assert 0.0 <= float(scores.pop()) <= 1.0
    assert probabilities  # some session (an Active one) had queries
