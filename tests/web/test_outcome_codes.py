"""A completion code per outcome: each participant is shown the code of how their study ended, redirected with it,
and the code and the reason are in participants.csv and the dashboard's tables; old single screened-out codes work."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from datetime import timedelta
from pathlib import Path
from typing import Any

from tableteach.db.migrate import REPO_ROOT

from .helpers import EXP, bearer, join, make_study, to_teaching
from .test_study_ops import SHORT, URL, finish, rows

CODES = {"completion_code": "DONE1", "declined_consent_code": "NOCONSENT2", "failed_quiz_code": "QUIZ3",
         "failed_attention_code": "ATTN4", "timed_out_code": "LATE5", "withdrew_code": "LEFT6"}
QUIZ = [{"id": "who", "text": "Who places the objects?", "options": ["I do", "The robot"], "correct": 1}]
ITEMS = [{"id": "learned", "text": "The robot learned.", "kind": "likert5"},
         {"id": "attn", "text": "Please choose Disagree.", "kind": "attention", "expected": 2}]


def _consent(client: Any, token: str, agree: bool = True) -> dict[str, Any]:
    r = client.post("/api/v1/me/consent", json={"agree": agree, "consent_version": "1"}, headers=bearer(token))
    assert r.status_code == 200, r.text
    return r.json()


def _quiz_failed(client: Any, study: str) -> dict[str, Any]:
    token, _ = join(client, study)
    _consent(client, token)
    client.post("/api/v1/me/instructions", headers=bearer(token))
    return client.post("/api/v1/me/quiz", json={"answers": {"who": 0}}, headers=bearer(token)).json()


def _passed_quiz(client: Any, token: str) -> None:
    r = client.post("/api/v1/me/quiz", json={"answers": {"who": 1}}, headers=bearer(token))
    assert r.status_code == 200 and r.json()["stage"] == "task", r.text


def _idle(client: Any, token: str, minutes: int) -> None:
    from tableteach.db.tables import ParticipantRow

    with client.ctx.db.write() as s:
        p = s.query(ParticipantRow).filter_by(token=token).one()
        p.last_activity_at = p.last_activity_at - timedelta(minutes=minutes)
        s.commit()


def _finish_after_quiz(client: Any, study: str, answers: dict[str, Any]) -> dict[str, Any]:
    from .helpers import demonstrate

    token, state = to_teaching(client, study)
    _passed_quiz(client, token)
    state = client.get("/api/v1/me", headers=bearer(token)).json()
    while state["stage"] == "task":
        state = demonstrate(client, token, ["dinner_plate", "bowl"])
    r = client.post("/api/v1/me/questionnaire", json={"answers": answers}, headers=bearer(token))
    assert r.status_code == 200, r.text
    return r.json()


def test_every_outcome_has_its_own_code_in_the_redirect_the_export_and_the_dashboard(app_client) -> None:
    study = make_study(app_client, quiz=QUIZ, quiz_max_attempts=1, questionnaire=ITEMS, timeout_minutes=5,
                       completion_url=URL, **CODES, **SHORT)
    shown: dict[str, dict[str, Any]] = {}
    shown["completed"] = _finish_after_quiz(app_client, study, {"learned": 4, "attn": 2})
    shown["attention"] = _finish_after_quiz(app_client, study, {"learned": 4, "attn": 5})
    token, _ = join(app_client, study)
    shown["declined_consent"] = _consent(app_client, token, agree=False)
    shown["comprehension"] = _quiz_failed(app_client, study)
    token, _ = to_teaching(app_client, study)
    _passed_quiz(app_client, token)
    _idle(app_client, token, 6)
    from tableteach.services.timeouts import sweep_timeouts

    sweep_timeouts(app_client.ctx)  # the runtime's periodic sweep (reads never screen anyone out)
    shown["timeout"] = app_client.get("/api/v1/me", headers=bearer(token)).json()
    token, _ = to_teaching(app_client, study)
    shown["withdrew"] = app_client.post("/api/v1/me/withdraw", headers=bearer(token)).json()
    expected = dict(zip(["completed", "declined_consent", "comprehension", "attention", "timeout", "withdrew"],
                        CODES.values(), strict=True))
    for outcome, state in shown.items():
        code = expected[outcome]
        assert state["completion"]["code"] == code, (outcome, state["completion"])
        assert state["completion"]["redirect_url"] == URL.replace("{code}", code), outcome
    people = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}
    listed = {p["participant_id"]: p for p in
              app_client.get(f"/api/v1/studies/{study}/participants", headers=EXP).json()}
    live = {p["participant_id"]: p for p in
            app_client.get(f"/api/v1/studies/{study}/live", headers=EXP).json()["participants"]}
    for outcome, state in shown.items():
        pid = state["participant_id"]
        assert (people[pid]["completion_code"], people[pid]["outcome"]) == (expected[outcome], outcome)
        assert (listed[pid]["completion_code"], listed[pid]["outcome"]) == (expected[outcome], outcome)
        assert (live[pid]["completion_code"], live[pid]["outcome"]) == (expected[outcome], outcome)
    codebook = app_client.get(f"/api/v1/studies/{study}/exports/codebook.csv", headers=EXP).text
    assert "participants.csv,outcome,category" in codebook and "timeout (timed out" in codebook


def test_an_old_single_screened_out_code_covers_the_outcomes_without_their_own(app_client) -> None:
    study = make_study(app_client, quiz=QUIZ, quiz_max_attempts=1, completion_url=URL, completion_code="OK1",
                       screened_out_code="OLD2", failed_quiz_code="QUIZ3", **SHORT)
    token, _ = join(app_client, study)
    assert _consent(app_client, token, agree=False)["completion"]["code"] == "OLD2"
    assert _quiz_failed(app_client, study)["completion"]["code"] == "QUIZ3"
    token, _ = to_teaching(app_client, study)
    _passed_quiz(app_client, token)
    withdrawn = app_client.post("/api/v1/me/withdraw", headers=bearer(token)).json()
    assert withdrawn["completion"] == {"code": None, "reason": "withdrew", "redirect_url": None, "learned": [],
                                       "return_url": "https://app.prolific.com/"}
    spec = app_client.get(f"/api/v1/studies/{study}", headers=EXP).json()
    assert spec["screened_out_code"] == "OLD2" and spec["timed_out_code"] is None


def test_outcome_codes_can_change_on_an_open_study_and_bad_ones_are_named(app_client) -> None:
    study = make_study(app_client, **SHORT)
    url = f"/api/v1/studies/{study}"
    r = app_client.patch(url, json={"timed_out_code": "LATE9"}, headers=EXP)
    assert r.status_code == 200 and r.json()["timed_out_code"] == "LATE9"
    r = app_client.patch(url, json={"failed_quiz_code": "has space"}, headers=EXP)
    assert r.status_code == 422 and [e["field"] for e in r.json()["errors"]] == ["failed_quiz_code"]
    assert finish(app_client, study)["completion"]["code"]  # no completion code: a fresh one each


def test_the_migration_stores_the_code_old_screened_out_participants_were_shown(tmp_path: Path) -> None:
    db = tmp_path / "old.db"
    env = {**os.environ, "TABLETEACH_DATABASE_URL": f"sqlite:///{db}"}
    alembic = [sys.executable, "-m", "alembic", "-c", str(REPO_ROOT / "alembic.ini")]
    up = subprocess.run(alembic + ["upgrade", "0004_participant_ux"], env=env, capture_output=True, text=True)
    assert up.returncode == 0, up.stderr
    with sqlite3.connect(db) as con:
        con.execute("insert into studies (id, name, tasks, conditions, assignment, n_practice, n_demonstrations, "
                    "n_queries, n_tests, prior, criterion, questionnaire, consent_text, consent_version, status, "
                    "pilot, screened_out_code, created_at, updated_at) values ('s1', 'old', '[]', '[]', 'random', "
                    "0, 1, 0, 0, 'p', 'c', '[]', 'x', '1', 'open', 0, 'OLD7', '2026-01-01', '2026-01-01')")
        for pid, stage, reason, code in ((1, "screened_out", "timeout", None), (2, "withdrawn", "withdrew", None),
                                         (3, "done", None, "FIN"), (4, "withdrawn", "declined_consent", None)):
            con.execute("insert into participants (id, token, uid, study_id, condition, seed, pilot, stage, "
                        "task_index, completion_code, created_at, last_activity_at, n_events, end_reason, version) "
                        f"values ({pid}, 't{pid}', 'u{pid}', 's1', 'active', 1, 0, '{stage}', 0, "
                        f"{'NULL' if code is None else repr(code)}, '2026-01-01', '2026-01-01', 0, "
                        f"{'NULL' if reason is None else repr(reason)}, 1)")
    up = subprocess.run(alembic + ["upgrade", "head"], env=env, capture_output=True, text=True)
    assert up.returncode == 0, up.stderr
    with sqlite3.connect(db) as con:
        codes = dict(con.execute("select id, completion_code from participants order by id").fetchall())
        columns = {r[1] for r in con.execute("pragma table_info(studies)")}
    assert codes == {1: "OLD7", 2: None, 3: "FIN", 4: "OLD7"}
    assert {"timed_out_code", "withdrew_code", "failed_quiz_code"} <= columns
