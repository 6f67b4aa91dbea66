"""Exports a statistician reads without a note: beliefs join steps on a shared key, acceptable means the same in
both, n_events matches events.csv, everyone has an elapsed time, a withdrawn row keeps only the withdrawal, and
exports.zip is a valid Frictionless Data Package generated from the codebook."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
import zipfile
from collections import Counter
from pathlib import Path

import pytest

from .helpers import EXP, bearer, demonstrate, join, make_study, to_teaching
from .test_study_ops import rows

SPEC = {"n_practice": 1, "n_demonstrations": 2, "n_queries": 2, "n_tests": 1, "conditions": ["active"]}


def _teach_all(client, study: str) -> dict:  # type: ignore[no-untyped-def]
    """A participant through every step (the trace robot executes instantly enough to poll)."""
    token, state = to_teaching(client, study)
    h = bearer(token)
    while state["stage"] == "task":
        kind = state["step"]["kind"]
        if kind in ("practice", "demonstration"):
            state = demonstrate(client, token, ["dinner_plate", "bowl"])
            continue
        if state["execution"]["status"] == "not_started":
            state = client.post("/api/v1/me/execution", headers=h).json()
        while state["execution"]["status"] != "finished":
            state = client.get("/api/v1/me", headers=h).json()
        state = client.post("/api/v1/me/assessment", json={"acceptable": kind == "query"}, headers=h).json()
    return client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4, "overall": 7}}, headers=h).json()


def test_beliefs_join_steps_and_acceptable_means_the_same_in_both(app_client) -> None:
    study = make_study(app_client, **{k: v for k, v in SPEC.items() if k != "conditions"})
    _teach_all(app_client, study)
    steps = rows(app_client, study, "steps")
    beliefs = {(b["participant_id"], b["task_index"], b["step"]): b for b in rows(app_client, study, "beliefs")}
    learned = [s for s in steps if s["learning_step"]]
    assert [s["step_kind"] for s in learned] == ["demonstration", "demonstration", "query", "query"]
    for s in learned:
        b = beliefs[(s["participant_id"], s["task_index"], s["learning_step"])]
        assert (b["record_kind"], b["step_kind"], b["step_index"]) == (s["step_kind"], s["step_kind"], s["step_index"])
        assert b["acceptable"] == s["acceptable"], (b, s)
    assert {s["acceptable"] for s in steps if s["step_kind"] in ("practice", "demonstration")} == {"true"}
    assert not [s for s in steps if s["step_kind"] in ("practice", "test") and s["learning_step"]]
    prior = beliefs[(steps[0]["participant_id"], steps[0]["task_index"], "0")]
    assert prior["step_kind"] == "" and prior["record_kind"] == ""


def test_n_events_elapsed_time_and_a_withdrawn_row_that_keeps_only_the_withdrawal(app_client) -> None:
    study = make_study(app_client, **SPEC)
    done = _teach_all(app_client, study)
    token, state = join(app_client, study, prolific_pid="PROLIFIC_W1", session_id="S1")
    app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=bearer(token))
    app_client.post("/api/v1/me/instructions", headers=bearer(token))
    app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token))
    gone = app_client.post("/api/v1/me/withdraw", headers=bearer(token)).json()
    waiting, _ = join(app_client, study)
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    counts = Counter(int(e["participant_id"]) for e in rows(app_client, study, "events"))
    for pid, person in people.items():
        assert int(person["n_events"]) == counts[pid], person
        if person["stage"] != "withdrawn":  # (of whom only the fact of the withdrawal is kept)
            assert person["elapsed_seconds"] != "", person  # everyone else, under way or not
    assert people[done["participant_id"]]["total_seconds"] != ""
    withdrawn = people[gone["participant_id"]]
    assert withdrawn["stage"] == "withdrawn" and withdrawn["end_reason"] == "withdrew"
    assert withdrawn["prolific_pid"] == withdrawn["external_session_id"] == withdrawn["condition"] == ""
    assert withdrawn["consent_at"] == withdrawn["seed"] == withdrawn["created_at"] == ""
    assert "PROLIFIC_W1" not in app_client.get(f"/api/v1/studies/{study}/exports/exports.zip", headers=EXP).text
    listed = {p["participant_id"]: p for p in app_client.get(f"/api/v1/studies/{study}/participants",
                                                             headers=EXP).json()}
    assert listed[gone["participant_id"]]["prolific_pid"] is None  # not kept in the database either


FRICTIONLESS = shutil.which("frictionless") or str(Path(sys.executable).parent / "frictionless")


@pytest.mark.skipif(not Path(FRICTIONLESS).exists(), reason="frictionless is not installed")
def test_exports_zip_is_a_valid_frictionless_data_package(app_client, tmp_path: Path) -> None:
    items = [{"id": "learned", "text": "The robot learned.", "kind": "likert5"},
             {"id": "overall", "text": "Overall", "kind": "rating10"},
             {"id": "comments", "text": "Comments, e.g. =1+1", "kind": "text", "required": False}]
    study = make_study(app_client, questionnaire=items, **SPEC)
    _teach_all(app_client, study)
    to_teaching(app_client, study)  # one under way: empty cells
    r = app_client.get(f"/api/v1/studies/{study}/exports/exports.zip", headers=EXP)
    zipfile.ZipFile(io.BytesIO(r.content)).extractall(tmp_path)
    package = json.loads((tmp_path / "datapackage.json").read_text())
    codebook = rows(app_client, study, "codebook")
    described = {(c["file"], c["column"]) for c in codebook if not c["column"].startswith("answer where")}
    assert {(f"{res['name']}.csv", f["name"]) for res in package["resources"] if res["name"] != "codebook"
            for f in res["schema"]["fields"]} == described
    done = subprocess.run([FRICTIONLESS, "validate", "datapackage.json"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
