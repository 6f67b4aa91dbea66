"""Running a real study: completion codes, withdrawal and erasure, counterbalancing, checks, pilots, edits,
timeouts and the exports a statistician reads (codebook, steps, exports.zip)."""

from __future__ import annotations

import csv
import io
import json
import re
import zipfile
from datetime import timedelta
from itertools import permutations
from typing import Any

from .helpers import EXP, bearer, demonstrate, join, make_study, participant_uid, to_teaching

URL = "https://app.prolific.com/submissions/complete?cc={code}"
SHORT = {"n_practice": 0, "n_demonstrations": 1, "n_queries": 0, "n_tests": 0, "conditions": ["batch"]}
ANSWERS = {"learned": 4, "overall": 7}


def rows(client: Any, study: str, name: str, **params: Any) -> list[dict[str, str]]:
    """One export parsed as dictionaries."""
    r = client.get(f"/api/v1/studies/{study}/exports/{name}.csv", params=params, headers=EXP)
    assert r.status_code == 200, r.text
    return list(csv.DictReader(io.StringIO(r.text)))


def finish(client: Any, study: str, answers: dict[str, Any] | None = None) -> dict[str, Any]:
    """A participant who goes through one demonstration per task and the questionnaire; the final state."""
    token, state = to_teaching(client, study)
    while state["stage"] == "task":
        state = demonstrate(client, token, ["dinner_plate", "bowl"])
    r = client.post("/api/v1/me/questionnaire", json={"answers": answers or ANSWERS}, headers=bearer(token))
    assert r.status_code == 200, r.text
    return r.json()


def test_study_level_codes_redirect_finishers_and_those_who_decline(app_client) -> None:
    study = make_study(app_client, completion_url=URL, completion_code="C0DE1", screened_out_code="SCREEN2", **SHORT)
    done = [finish(app_client, study) for _ in range(2)]
    assert {d["completion"]["code"] for d in done} == {"C0DE1"}  # the code Prolific was told, not a fresh one
    assert done[0]["completion"]["redirect_url"] == URL.replace("{code}", "C0DE1")
    token, state = join(app_client, study)
    declined = app_client.post("/api/v1/me/consent", json={"agree": False, "consent_version": "1"},
                               headers=bearer(token)).json()
    assert declined["stage"] == "withdrawn"
    assert declined["completion"]["reason"] == "declined_consent"
    assert declined["completion"]["redirect_url"] == URL.replace("{code}", "SCREEN2")
    # Without study-level codes, each participant still gets a code of their own.
    other = make_study(app_client, completion_url=URL, **SHORT)
    codes = {finish(app_client, other)["completion"]["code"] for _ in range(2)}
    assert len(codes) == 2


def test_withdrawal_deletes_the_data_and_is_visible_only_as_a_withdrawal(app_client) -> None:
    study = make_study(app_client, **SHORT)
    token, state = join(app_client, study)
    r = app_client.post("/api/v1/me/withdraw", headers=bearer(token))
    assert r.status_code == 409 and "consent" in r.json()["detail"]
    token, _ = to_teaching(app_client, study)
    app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token))
    keep = finish(app_client, study)
    r = app_client.post("/api/v1/me/withdraw", headers=bearer(token))
    assert r.status_code == 200 and r.json()["stage"] == "withdrawn"
    assert r.json()["completion"] == {"code": None, "reason": "withdrew", "redirect_url": None, "learned": [],
                                      "return_url": None}
    again = app_client.post("/api/v1/me/withdraw", headers=bearer(token))
    assert again.status_code == 200 and again.json()["n_events"] == r.json()["n_events"]
    pid = r.json()["participant_id"]
    events = rows(app_client, study, "events")
    assert [e["kind"] for e in events if int(e["participant_id"]) == pid] == ["withdrawn"]
    assert any(int(e["participant_id"]) == keep["participant_id"] for e in events)
    assert not [b for b in rows(app_client, study, "beliefs") if int(b["participant_id"]) == pid]
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    assert people[pid]["stage"] == "withdrawn" and people[pid]["end_reason"] == "withdrew"
    consent = app_client.get(f"/api/v1/studies/{study}", headers=EXP).json()["consent_text"]
    assert "Withdraw" in consent and "deleted" in consent


def test_erasure_removes_everything_keeps_an_audit_entry_and_is_idempotent(app_client) -> None:
    study = make_study(app_client, **SHORT)
    gone = finish(app_client, study)
    kept = finish(app_client, study)
    data_dir = app_client.ctx.settings.data_dir
    gone_uid = participant_uid(app_client.ctx, gone["participant_id"])
    folder = data_dir / "recordings" / f"participant-{gone_uid}" / "task-0"
    folder.mkdir(parents=True)
    (folder / "demonstration-0.json").write_text("{}")
    other = data_dir / "recordings" / f"participant-{participant_uid(app_client.ctx, kept['participant_id'])}"
    other.mkdir(parents=True)
    url = f"/api/v1/studies/{study}/participants/{gone['participant_id']}"
    assert app_client.delete(url, headers=EXP).status_code == 204
    assert app_client.delete(url, headers=EXP).status_code == 204
    assert app_client.delete(f"/api/v1/studies/{study}/participants/999999", headers=EXP).status_code == 404
    assert app_client.delete(url).status_code == 401
    assert not folder.parent.exists() and other.exists()
    for name in ("participants", "events", "steps", "beliefs", "questionnaire"):
        assert {int(r["participant_id"]) for r in rows(app_client, study, name)} == {kept["participant_id"]}, name
    assert app_client.get("/api/v1/me", headers=bearer(gone["token"])).status_code == 401
    audit = app_client.get(f"/api/v1/studies/{study}/erasures", headers=EXP).json()
    assert len(audit) == 1 and audit[0]["participant_id"] == gone["participant_id"]
    assert audit[0]["erased_by"] == "owner (server key)" and audit[0]["reason"] == "erasure"
    assert set(audit[0]) == {"participant_id", "erased_by", "reason", "pilot", "erased_at"}
    # The number is never given to someone else.
    assert join(app_client, study)[1]["participant_id"] > kept["participant_id"]


def test_balanced_task_order_crossed_with_conditions(app_client) -> None:
    tasks = [{"key": "task1"}, {"key": "task2"}, {"key": "none"}]
    study = make_study(app_client, tasks=tasks, conditions=["active", "batch"], assignment="balanced",
                       task_order="balanced")
    cells = [(c, list(o)) for c in ("active", "batch") for o in permutations(range(3))]
    for _ in range(len(cells) + 3):
        join(app_client, study)
    people = rows(app_client, study, "participants")
    counts = [sum(p["condition"] == c and json.loads(p["task_order"]) == o for p in people) for c, o in cells]
    assert sum(counts) == len(cells) + 3 and max(counts) - min(counts) <= 1


def test_a_participant_does_the_tasks_in_their_own_order(app_client) -> None:
    study = make_study(app_client, tasks=[{"key": "task1"}, {"key": "task2"}], task_order="random", **SHORT)
    orders = set()
    for _ in range(12):
        token, state = to_teaching(app_client, study)
        order = json.loads(next(p for p in rows(app_client, study, "participants")
                                if int(p["participant_id"]) == state["participant_id"])["task_order"])
        orders.add(tuple(order))
        assert state["task"]["index"] == order[0] and state["task"]["position"] == 0
        state = demonstrate(app_client, token, ["dinner_plate"])
        assert state["task"]["index"] == order[1] and state["task"]["position"] == 1
    assert orders == {(0, 1), (1, 0)}  # 12 draws: both orders (each missing with probability 2^-11)


def test_the_practice_trial_comes_before_the_task_a_participant_does_first(app_client) -> None:
    study = make_study(app_client, tasks=[{"key": "task1"}, {"key": "task2"}], task_order="random",
                       **{**SHORT, "n_practice": 1})
    seen = set()
    for _ in range(12):
        token, state = to_teaching(app_client, study)
        first = state["task"]["index"]
        seen.add(first)
        assert state["step"]["kind"] == "practice", f"task {first} done first starts without its practice trial"
        state = demonstrate(app_client, token, ["dinner_plate"])  # the practice trial
        state = demonstrate(app_client, token, ["dinner_plate"])  # the one demonstration of the first task
        assert state["task"]["position"] == 1 and state["step"]["kind"] == "demonstration"
    assert seen == {0, 1}  # both tasks came first at least once (each missing with probability 2^-11)


def test_comprehension_quiz_passes_or_screens_out(app_client) -> None:
    quiz = [{"id": "who", "text": "Who places the objects?", "options": ["I do", "The robot"], "correct": 1},
            {"id": "order", "text": "Can the order matter?", "options": ["Yes", "No"], "correct": 0}]
    study = make_study(app_client, quiz=quiz, quiz_max_attempts=2, completion_url=URL, screened_out_code="NOPE",
                       **SHORT)
    token, state = join(app_client, study)
    h = bearer(token)
    app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=h)
    state = app_client.post("/api/v1/me/instructions", headers=h).json()
    assert state["stage"] == "quiz" and state["quiz"]["attempts_left"] == 2
    assert "correct" not in state["quiz"]["items"][0]  # the answers stay on the server
    r = app_client.post("/api/v1/me/quiz", json={"answers": {"who": 1}}, headers=h)
    assert r.status_code == 422 and "order" in r.json()["detail"]
    state = app_client.post("/api/v1/me/quiz", json={"answers": {"who": 0, "order": 0}}, headers=h).json()
    assert state["stage"] == "quiz" and state["quiz"]["attempts_left"] == 1
    state = app_client.post("/api/v1/me/quiz", json={"answers": {"who": 1, "order": 0}}, headers=h).json()
    assert state["stage"] == "task"
    token, _ = join(app_client, study)
    h = bearer(token)
    app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=h)
    app_client.post("/api/v1/me/instructions", headers=h)
    for _ in range(2):
        state = app_client.post("/api/v1/me/quiz", json={"answers": {"who": 0, "order": 1}}, headers=h).json()
    assert state["stage"] == "screened_out" and state["completion"]["reason"] == "comprehension"
    assert state["completion"]["redirect_url"] == URL.replace("{code}", "NOPE")
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    assert people[state["participant_id"]]["quiz_failures"] == "2"


def test_attention_check_failures_are_flagged_never_dropped(app_client) -> None:
    items = [{"id": "learned", "text": "The robot learned.", "kind": "likert5"},
             {"id": "attn", "text": "Please choose Disagree.", "kind": "attention", "expected": 2}]
    study = make_study(app_client, questionnaire=items, completion_code="OK1", screened_out_code="NO2",
                       completion_url=URL, **SHORT)
    good = finish(app_client, study, {"learned": 5, "attn": 2})
    bad = finish(app_client, study, {"learned": 5, "attn": 4})
    assert good["completion"]["code"] == "OK1" and bad["completion"]["code"] == "NO2"
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    assert people[good["participant_id"]]["attention_failed"] == "false"
    assert people[bad["participant_id"]]["attention_failed"] == "true"
    answers = [r for r in rows(app_client, study, "questionnaire") if r["item_id"] == "attn"]
    assert {(int(r["participant_id"]), r["attention_passed"]) for r in answers} == {
        (good["participant_id"], "true"), (bad["participant_id"], "false")}
    live = {p["participant_id"]: p for p in app_client.get(f"/api/v1/studies/{study}/live", headers=EXP).json()[
        "participants"]}
    assert live[bad["participant_id"]]["attention_failed"] is True
    assert live[good["participant_id"]]["attention_failed"] is False


def test_pilots_are_left_out_unless_asked_for_and_the_reset_erases_only_them(app_client) -> None:
    study = make_study(app_client, pilot=True, **SHORT)
    pilot = finish(app_client, study)
    r = app_client.patch(f"/api/v1/studies/{study}", json={"pilot": False}, headers=EXP)
    assert r.status_code == 200 and r.json()["pilot"] is False
    real = finish(app_client, study)
    assert [int(p["participant_id"]) for p in rows(app_client, study, "participants")] == [real["participant_id"]]
    both = rows(app_client, study, "participants", include_pilot="true")
    assert {(int(p["participant_id"]), p["pilot"]) for p in both} == {
        (pilot["participant_id"], "true"), (real["participant_id"], "false")}
    curves = app_client.get(f"/api/v1/studies/{study}/curves", headers=EXP).json()
    assert [x["participant_id"] for x in curves["tasks"][0]["participants"]] == [real["participant_id"]]
    r = app_client.post(f"/api/v1/studies/{study}/pilot/reset", headers=EXP)
    assert r.status_code == 200 and r.json()["erased"] == [pilot["participant_id"]]
    both = rows(app_client, study, "participants", include_pilot="true")
    assert [int(p["participant_id"]) for p in both] == [real["participant_id"]]
    assert app_client.post(f"/api/v1/studies/{study}/pilot/reset", headers=EXP).json()["erased"] == []


def test_patch_edits_a_draft_and_only_the_safe_fields_of_an_open_study(app_client) -> None:
    created = app_client.post("/api/v1/studies", json={"tasks": [{"key": "task1"}], "name": "A"}, headers=EXP).json()
    url = f"/api/v1/studies/{created['id']}"
    custom = {"key": "custom", "ground_truth": "F(bowl) & (!fork U knife)", "name": "Bowl first",
              "instructions": "Put the knife before the fork."}
    r = app_client.patch(url, json={"tasks": [custom], "n_queries": 5, "task_order": "random",
                                    "conditions": ["active", "random"]}, headers=EXP)
    assert r.status_code == 200, r.text
    study = r.json()
    assert study["n_queries"] == 5 and study["tasks"][0]["name"] == "Bowl first" and study["name"] == "A"
    assert study["conditions"] == ["active", "random"] and study["task_order"] == "random"
    r = app_client.patch(url, json={"n_queries": 99, "prior": "nope"}, headers=EXP)
    assert r.status_code == 422 and {e["field"] for e in r.json()["errors"]} == {"n_queries", "prior"}
    assert app_client.get(url, headers=EXP).json()["n_queries"] == 5  # nothing stored is lost
    app_client.post(f"{url}/open", headers=EXP)
    r = app_client.patch(url, json={"n_queries": 1}, headers=EXP)
    assert r.status_code == 409 and "n_queries" in r.json()["detail"] and "clone" in r.json()["detail"]
    r = app_client.patch(url, json={"name": "B", "completion_code": "XYZ"}, headers=EXP)
    assert r.status_code == 200 and r.json()["name"] == "B" and r.json()["completion_code"] == "XYZ"
    clone = app_client.post(f"{url}/clone", headers=EXP)
    assert clone.status_code == 201
    copy = clone.json()
    assert copy["id"] != created["id"] and copy["status"] == "draft" and copy["name"] == "Copy of B"
    assert copy["tasks"] == study["tasks"] and copy["completion_code"] == "XYZ"
    assert app_client.get(url, headers=EXP).json()["status"] == "open"
    assert app_client.post("/api/v1/studies/nope/clone", headers=EXP).status_code == 404


def test_every_bad_field_is_reported_at_once(app_client) -> None:
    spec = {"tasks": [{"key": "custom", "ground_truth": "F(spoon)"}, {"key": "custom"}], "n_tests": -1,
            "conditions": ["active", "active"], "task_order": "shuffled", "completion_code": "has space",
            "quiz": [{"id": "q", "text": "?", "options": ["a", "b"], "correct": 5}],
            "questionnaire": [{"id": "a", "text": "Pick 2", "kind": "attention"}]}
    r = app_client.post("/api/v1/studies", json=spec, headers=EXP)
    assert r.status_code == 422
    fields = {e["field"] for e in r.json()["errors"]}
    assert {"tasks.0.ground_truth", "tasks.1.ground_truth", "n_tests", "conditions", "task_order",
            "completion_code", "quiz.0.correct", "questionnaire.0.expected"} <= fields, fields
    assert "spoon" in r.json()["detail"]
    ok = app_client.get("/api/v1/formulas/describe", params={"formula": "(!fork U knife) & F(bowl)"}, headers=EXP)
    assert ok.status_code == 200 and "knife" in ok.json()["description"]
    bad = app_client.get("/api/v1/formulas/describe", params={"formula": "F(spoon)"}, headers=EXP)
    assert bad.status_code == 422 and "spoon" in bad.json()["detail"]


def test_exports_booleans_durations_codebook_and_zip(app_client) -> None:
    study = make_study(app_client, tasks=[{"key": "task1"}, {"key": "task2"}], **SHORT)
    done = finish(app_client, study)
    people = rows(app_client, study, "participants")
    assert people[0]["pilot"] == "false" and people[0]["timed_out"] == "false"
    assert people[0]["task_order"] == "[0,1]" and float(people[0]["total_seconds"]) >= 0
    steps = rows(app_client, study, "steps")
    assert [(s["task"], s["step_kind"], s["task_position"]) for s in steps] == [
        ("task1", "demonstration", "0"), ("task2", "demonstration", "1")]
    assert all(float(s["duration_seconds"]) >= 0 and s["shown_at"] <= s["answered_at"] for s in steps)
    for name in ("events", "beliefs"):
        text = app_client.get(f"/api/v1/studies/{study}/exports/{name}.csv", headers=EXP).text
        assert ",True," not in text and ",False," not in text
    codebook = rows(app_client, study, "codebook")
    described = {(r["file"], r["column"]) for r in codebook}
    for name in ("participants", "events", "steps", "beliefs", "questionnaire", "scores"):
        header = app_client.get(f"/api/v1/studies/{study}/exports/{name}.csv", headers=EXP).text.splitlines()[0]
        assert {(f"{name}.csv", c) for c in header.split(",")} <= described, name
    assert any(r["column"] == "answer where item_id = learned" and "Strongly agree" in r["likert_labels"]
               for r in codebook)
    r = app_client.get(f"/api/v1/studies/{study}/exports/exports.zip", headers=EXP)
    assert r.status_code == 200 and r.headers["content-type"] == "application/zip"
    archive = zipfile.ZipFile(io.BytesIO(r.content))
    assert sorted(archive.namelist()) == sorted(["participants.csv", "events.csv", "steps.csv", "beliefs.csv",
                                                 "questionnaire.csv", "scores.csv", "codebook.csv", "study.json",
                                                 "datapackage.json"])
    assert json.loads(archive.read("study.json"))["id"] == study
    assert str(done["participant_id"]) in archive.read("participants.csv").decode()
    assert app_client.get("/api/v1/studies/nope/exports/codebook.csv", headers=EXP).status_code == 404


def test_idle_past_the_timeout_is_screened_out_and_kept(app_client) -> None:
    from tableteach.db.tables import ParticipantRow

    study = make_study(app_client, timeout_minutes=5, screened_out_code="LATE", completion_url=URL, **SHORT)
    token, _ = to_teaching(app_client, study)
    other, _ = to_teaching(app_client, study)
    with app_client.ctx.db.write() as s:
        for p in s.query(ParticipantRow).filter(ParticipantRow.token.in_([token, other])):
            p.last_activity_at = p.last_activity_at - timedelta(minutes=6)
        s.commit()
    r = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token))
    assert r.status_code == 409 and r.json()["state"]["stage"] == "screened_out"
    state = app_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["completion"] == {"code": "LATE", "reason": "timeout", "learned": [],
                                   "redirect_url": URL.replace("{code}", "LATE"), "return_url": None}
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    assert [p["timed_out"] for p in people.values()] == ["true", "false"]  # an export only reads
    from tableteach.services.timeouts import sweep_timeouts

    assert sweep_timeouts(app_client.ctx) == 1  # the runtime's periodic sweep screens the other one out
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    assert [p["timed_out"] for p in people.values()] == ["true", "true"]
    events = rows(app_client, study, "events")
    assert {e["kind"] for e in events} >= {"instructions_read", "task_started", "screened_out"}


def test_the_front_page_points_to_the_dashboard(app_client) -> None:
    r = app_client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert 'href="/dashboard"' in r.text and "link you were given" in r.text
    # Every link on it answers: /docs only exists in dev mode, so production links the schema instead.
    for href in re.findall(r'href="(/[^"]*)"', r.text):
        assert app_client.get(href).status_code == 200, href


def test_bad_input_to_the_new_endpoints_names_the_field(app_client) -> None:
    study = make_study(app_client, **SHORT)
    r = app_client.patch(f"/api/v1/studies/{study}", json={"colour": "red"}, headers=EXP)
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "colour"
    r = app_client.delete(f"/api/v1/studies/{study}/participants/0", headers=EXP)
    assert r.status_code == 422 and "participant_id" in r.json()["detail"]
    r = app_client.get(f"/api/v1/studies/{study}/exports/steps.csv?include_pilot=maybe", headers=EXP)
    assert r.status_code == 422 and "include_pilot" in r.json()["detail"]
    assert app_client.post("/api/v1/studies/nope/pilot/reset", headers=EXP).status_code == 404
    assert app_client.delete("/api/v1/studies/nope/participants/1", headers=EXP).status_code == 404
    token, _ = to_teaching(app_client, study)
    r = app_client.post("/api/v1/me/quiz", json={"answers": {"who": "first"}}, headers=bearer(token))
    assert r.status_code == 422 and "answers.who" in r.json()["detail"]
    r = app_client.post("/api/v1/me/quiz", json={"answers": {}}, headers=bearer(token))
    assert r.status_code == 409 and "quiz stage" in r.json()["detail"]


def test_questionnaire_and_quiz_items_need_ids_not_used_before(app_client) -> None:
    from .conftest import study_spec

    spec = study_spec(["active"])
    spec["questionnaire"] = [{"id": "q", "text": "One", "kind": "likert5"}, {"id": "q", "text": "Two", "kind": "text"},
                             {"text": "No id", "kind": "likert5"}]
    spec["quiz"] = [{"id": "z", "text": "A?", "options": ["x", "y"], "correct": 0},
                    {"id": "z", "text": "B?", "options": ["x", "y"], "correct": 1}]
    r = app_client.post("/api/v1/studies", json=spec, headers=EXP)
    assert r.status_code == 422
    assert {e["field"] for e in r.json()["errors"]} == {"questionnaire.1.id", "questionnaire.2.id", "quiz.1.id"}
