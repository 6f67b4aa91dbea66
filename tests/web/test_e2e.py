"""End to end over HTTP: scripted teachers complete Active, Random and Batch sessions against a real server
process, and the CSV exports contain exactly what happened."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tableteach.client import ExperimenterClient, TeacherRun, run_teacher
from tableteach.core.domain import get_domain

from .conftest import EXPERIMENTER_TOKEN, ServerProcess, open_study, study_spec

pytestmark = pytest.mark.slow


def _csv(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


def _exports(url: str, study_id: str) -> dict[str, list[dict[str, str]]]:
    exp = ExperimenterClient(url, token=EXPERIMENTER_TOKEN)
    try:
        return {name: _csv(exp.export(study_id, name))
                for name in ("participants", "events", "beliefs", "questionnaire")}
    finally:
        exp.close()


def _check_exports_match(run: TeacherRun, exports: dict[str, list[dict[str, str]]], protocol: str) -> None:
    """Every teacher action appears in events.csv with the same objects, traces and verdicts, in order."""
    pid = str(run.participant_id)
    events = [e for e in exports["events"] if e["participant_id"] == pid]
    assert [int(e["seq"]) for e in events] == list(range(1, len(events) + 1))
    placements = [e for e in events if e["kind"] == "place"]
    demos = [e for e in events if e["kind"] == "demonstration"]
    assessments = [e for e in events if e["kind"] == "assessment"]
    taught = [a for a in run.actions if a["kind"] in ("practice", "demonstration")]
    robot = [a for a in run.actions if a["kind"] in ("query", "test")]
    assert [e["object"] for e in placements] == [obj for a in taught for obj in a["events"]]
    assert [json.loads(e["trace"]) for e in demos] == [a["trace"] for a in taught]
    assert [e["step_kind"] for e in demos] == [a["kind"] for a in taught]
    assert [(e["step_kind"], json.loads(e["robot_events"]), json.loads(e["trace"]), e["acceptable"])
            for e in assessments] == [
        (a["kind"], a["events"], a["trace"], {True: "true", False: "false", None: ""}[a["acceptable"]]) for a in robot
    ]
    # Robot traces are what the robot reported: for the trace robot, the labels of its placements.
    domain = get_domain("dinner")
    for a in robot:
        assert a["trace"] == [sorted(s) for s in domain.trace_of(a["events"])]
    n_queries = sum(a["kind"] == "query" for a in robot)
    n_demos = sum(a["kind"] == "demonstration" for a in taught)
    assert (n_demos, n_queries) == ((5, 0) if protocol == "batch" else (2, 3))
    assert sum(a["kind"] == "test" for a in robot) == 3
    assert sum(a["kind"] == "practice" for a in taught) == 1
    assert events[-1]["kind"] == "completed"

    participant = [p for p in exports["participants"] if p["participant_id"] == pid]
    assert len(participant) == 1
    assert participant[0]["stage"] == "done" and participant[0]["condition"] == protocol
    assert participant[0]["completion_code"] == run.completion_code
    assert int(participant[0]["n_events"]) == len(events)

    beliefs = [b for b in exports["beliefs"] if b["participant_id"] == pid]
    assert [int(b["step"]) for b in beliefs] == list(range(n_demos + n_queries + 1))
    assert beliefs[-1]["map_formula"] == run.final[-1]["map_formula"]
    assert 0.0 <= float(beliefs[-1]["similarity"]) <= 1.0

    answers = {q["item_id"]: q["answer"] for q in exports["questionnaire"] if q["participant_id"] == pid}
    given = next(a["answers"] for a in run.actions if a["kind"] == "questionnaire")
    expected = {k: ("'" + v if isinstance(v, str) and v.startswith("=") else str(v)) for k, v in given.items()}
    assert answers == expected
    assert answers["comments"] == "'=scripted teacher"  # a spreadsheet must not run it


@pytest.mark.parametrize("protocol", ["active", "random", "batch"])
def test_scripted_teacher_completes_each_protocol(shared_server: ServerProcess, protocol: str) -> None:
    study_id = open_study(shared_server.url, study_spec([protocol]))
    run = run_teacher(shared_server.url, study_id, ["task1"], seed=7)
    assert run.completion_code and len(run.final) == 1
    assert 0.0 <= run.final[0]["similarity"] <= 1.0
    _check_exports_match(run, _exports(shared_server.url, study_id), protocol)


def test_teach_and_export_commands_on_the_two_task_demo_study(tmp_path: Path) -> None:
    env_db = tmp_path / "demo.db"
    server = ServerProcess(env_db)
    server.start()
    try:
        # The demo study is seeded by `serve --demo`; seeding an already-migrated database again is harmless.
        from tableteach.config import Settings
        from tableteach.services import Context, seed_demo_study

        ctx = Context.from_settings(Settings(database_url=f"sqlite:///{env_db}"))
        assert seed_demo_study(ctx)["id"] == seed_demo_study(ctx)["id"] == "demo"
        ctx.db.dispose()
        cli = [sys.executable, "-m", "tableteach.cli"]
        out = subprocess.run(cli + ["teach", "--server", server.url, "--study", "demo", "--ground-truth", "task1",
                                    "--ground-truth", "task2", "--seed", "3", "--noise", "0.1"],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        summary = json.loads(out.stdout)
        assert [f["task_index"] for f in summary["final"]] == [0, 1]
        assert summary["map_formula"] == summary["final"][1]["map_formula"]
        assert len(summary["executions"]) == 12  # 3 queries + 3 tests per task

        export = cli + ["export", "--server", server.url, "--study", "demo", "--token", EXPERIMENTER_TOKEN]
        out = subprocess.run(export + ["--out", str(tmp_path / "csv")], capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert json.loads(out.stdout)["rows"]["participants"] == 0  # the demo study's participants are pilots
        out = subprocess.run(export + ["--out", str(tmp_path / "csv"), "--include-pilot"], capture_output=True,
                             text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert json.loads(out.stdout)["rows"]["participants"] == 1
        assert sorted(p.name for p in (tmp_path / "csv").iterdir()) == [
            "beliefs.csv", "codebook.csv", "datapackage.json", "events.csv", "participants.csv", "questionnaire.csv",
            "scores.csv", "steps.csv", "study.json"]

        bad = subprocess.run(cli + ["export", "--server", server.url, "--study", "demo", "--token", "wrong-token",
                                    "--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=60)
        assert bad.returncode == 2 and "wrong, expired or revoked experimenter token" in bad.stderr
        bad = subprocess.run(cli + ["teach", "--server", server.url, "--study", "demo", "--ground-truth", "F(spoon)"],
                             capture_output=True, text=True, timeout=60)
        assert bad.returncode == 2 and "spoon" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    finally:
        server.stop()


def test_serve_refuses_to_start_without_a_secret_outside_dev_mode(tmp_path: Path) -> None:
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith("TABLETEACH_")}
    out = subprocess.run([sys.executable, "-m", "tableteach.cli", "serve", "--port", "0", "--database-url",
                          f"sqlite:///{tmp_path / 'x.db'}"], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "TABLETEACH_EXPERIMENTER_TOKEN" in out.stderr
    assert not (tmp_path / "x.db").exists()
