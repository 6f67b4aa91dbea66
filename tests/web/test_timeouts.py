"""Time-outs without traps: a changed limit counts idleness from the change, a time-out finishes at the last
activity, and the experimenter can restore a screened-out participant or help a stuck one on (each logged)."""

from __future__ import annotations

from tableteach.services.timeouts import sweep_timeouts

from datetime import timedelta
from typing import Any

from .helpers import EXP, bearer, demonstrate, join, make_study, to_teaching
from .test_study_ops import SHORT, URL, rows

QUIZ = [{"id": "who", "text": "Who places the objects?", "options": ["I do", "The robot"], "correct": 1}]


def _age(client: Any, token: str, minutes: int) -> None:
    """Make a participant's last activity (and the join) this many minutes older."""
    from tableteach.db.tables import ParticipantRow

    with client.ctx.db.write() as s:
        p = s.query(ParticipantRow).filter_by(token=token).one()
        p.last_activity_at = p.last_activity_at - timedelta(minutes=minutes)
        p.created_at = p.created_at - timedelta(minutes=minutes)
        s.commit()


def _age_change(client: Any, study: str, minutes: int) -> None:
    from tableteach.db.tables import StudyRow

    with client.ctx.db.write() as s:
        row = s.get(StudyRow, study)
        row.timeout_changed_at = row.timeout_changed_at - timedelta(minutes=minutes)
        s.commit()


def _people(client: Any, study: str) -> dict[int, dict[str, Any]]:
    return {p["participant_id"]: p for p in client.get(f"/api/v1/studies/{study}/participants", headers=EXP).json()}


def test_lowering_the_limit_counts_only_idleness_after_the_change(app_client) -> None:
    study = make_study(app_client, timeout_minutes=60, **SHORT)
    token, state = to_teaching(app_client, study)
    pid = state["participant_id"]
    _age(app_client, token, 30)
    r = app_client.patch(f"/api/v1/studies/{study}", json={"timeout_minutes": 10}, headers=EXP)
    assert r.status_code == 200
    assert _people(app_client, study)[pid]["stage"] == "task"  # idle 30 min, but only 0 since the change
    assert app_client.get("/api/v1/me", headers=bearer(token)).json()["stage"] == "task"
    _age(app_client, token, 30)
    _age_change(app_client, study, 11)  # now idle 11 minutes since the change
    sweep_timeouts(app_client.ctx)  # the runtime's periodic sweep (reads never screen anyone out)
    assert _people(app_client, study)[pid]["stage"] == "screened_out"


def test_a_time_out_finishes_at_the_last_activity_and_restoring_continues_where_they_were(app_client) -> None:
    study = make_study(app_client, timeout_minutes=5, completion_url=URL, timed_out_code="LATE1", **SHORT)
    token, state = to_teaching(app_client, study)
    pid = state["participant_id"]
    assert app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token)).status_code == 200
    _age(app_client, token, 20)
    sweep_timeouts(app_client.ctx)  # the runtime's periodic sweep (reads never screen anyone out)
    before = _people(app_client, study)[pid]
    assert before["stage"] == "screened_out" and before["outcome"] == "timeout"
    assert before["finished_at"] == before["last_activity_at"]
    person = {int(p["participant_id"]): p for p in rows(app_client, study, "participants")}[pid]
    assert person["finished_at"] == person["last_activity_at"] and person["completion_code"] == "LATE1"
    r = app_client.post(f"/api/v1/studies/{study}/participants/{pid}/restore", headers=EXP)
    assert r.status_code == 200, r.text
    assert r.json()["stage"] == "task" and r.json()["completion_code"] is None and r.json()["finished_at"] is None
    state = app_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["stage"] == "task" and state["demonstration"]["placed"] == ["bowl"]  # their table is kept
    events = [e for e in rows(app_client, study, "events") if int(e["participant_id"]) == pid]
    assert [e["kind"] for e in events][-2:] == ["screened_out", "restored"]
    again = app_client.post(f"/api/v1/studies/{study}/participants/{pid}/restore", headers=EXP)
    assert again.status_code == 409 and "not screened out" in again.json()["detail"]


def test_restoring_a_failed_quiz_gives_fresh_attempts(app_client) -> None:
    study = make_study(app_client, quiz=QUIZ, quiz_max_attempts=1, **SHORT)
    token, state = join(app_client, study)
    h = bearer(token)
    app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=h)
    app_client.post("/api/v1/me/instructions", headers=h)
    state = app_client.post("/api/v1/me/quiz", json={"answers": {"who": 0}}, headers=h).json()
    assert state["stage"] == "screened_out"
    r = app_client.post(f"/api/v1/studies/{study}/participants/{state['participant_id']}/restore", headers=EXP)
    assert r.status_code == 200 and r.json()["stage"] == "quiz"
    state = app_client.get("/api/v1/me", headers=h).json()
    assert state["quiz"]["attempts_left"] == 1
    assert app_client.post("/api/v1/me/quiz", json={"answers": {"who": 1}}, headers=h).json()["stage"] == "task"


def test_helping_a_stuck_participant_on_moves_them_one_stage_and_is_logged(app_client) -> None:
    items = [{"id": "learned", "text": "The robot learned.", "kind": "likert5"}]
    study = make_study(app_client, quiz=QUIZ, questionnaire=items, tasks=[{"key": "task1"}, {"key": "task2"}],
                       **SHORT)
    token, state = join(app_client, study)
    pid = state["participant_id"]
    url = f"/api/v1/studies/{study}/participants/{pid}/help"
    r = app_client.post(url, headers=EXP)
    assert r.status_code == 409 and "consent is theirs" in r.json()["detail"]
    app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=bearer(token))
    stages = [app_client.post(url, headers=EXP).json()["stage"] for _ in range(5)]
    assert stages == ["quiz", "task", "task", "questionnaire", "done"]
    state = app_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["stage"] == "done" and state["completion"]["code"]
    helped = [e for e in rows(app_client, study, "events") if e["kind"] == "helped_on"]
    assert [e["payload"].count('"by":"owner (server key)"') for e in helped] == [1] * 5
    r = app_client.post(url, headers=EXP)
    assert r.status_code == 409 and "done" in r.json()["detail"]
    assert app_client.post(f"/api/v1/studies/{study}/participants/999/help", headers=EXP).status_code == 404
    assert app_client.post(url).status_code == 401


def test_a_task_helped_past_keeps_what_was_demonstrated(app_client) -> None:
    study = make_study(app_client, tasks=[{"key": "task1"}, {"key": "task2"}], **SHORT)
    token, state = to_teaching(app_client, study)
    state = demonstrate(app_client, token, ["dinner_plate"])
    assert state["task"]["position"] == 1
    r = app_client.post(f"/api/v1/studies/{study}/participants/{state['participant_id']}/help", headers=EXP)
    assert r.json()["stage"] == "questionnaire"  # the study's questionnaire follows the last task
    assert len([b for b in rows(app_client, study, "beliefs") if b["task"] == "task1"]) == 2  # prior + 1 demo
