"""The participant page's study settings and records (issue 21): the structured consent form, the quiz's
feedback, how much of the robot's attempt was shown before a verdict, through the in-process app."""

from __future__ import annotations

import csv
import io

from .helpers import EXP, bearer, demonstrate, join, make_study, to_teaching

CONSENT_FORM = {"researcher": "A. Researcher", "institution": "Example University", "contact": "lab@example.org",
                "ethics_approval": "Example University ethics board, ref. 2026-042", "duration": "About 15 minutes",
                "payment": "GBP 2.50 through Prolific", "retention": "Kept for five years, then deleted."}
QUIZ = [{"id": "who", "text": "Who places the objects?", "options": ["I do", "The robot"], "correct": 1},
        {"id": "order", "text": "Can the order matter?", "options": ["Yes", "No"], "correct": 0}]


def test_the_consent_form_is_shown_in_sections_and_its_digest_is_recorded_with_the_consent(app_client) -> None:
    study_id = make_study(app_client, consent_form=CONSENT_FORM, consent_version="2026-12-v3")
    spec = app_client.get(f"/api/v1/studies/{study_id}", headers=EXP).json()
    assert spec["consent_form"] == CONSENT_FORM and spec["allow_anonymous"] is False
    token, state = join(app_client, study_id)
    sections = {s["key"]: s for s in state["consent"]["sections"]}
    assert [s["key"] for s in state["consent"]["sections"]] == [
        "researcher", "institution", "contact", "ethics_approval", "duration", "payment", "recorded", "retention",
        "withdrawal"]
    assert sections["ethics_approval"]["text"] == CONSENT_FORM["ethics_approval"]
    assert "Withdraw" in sections["withdrawal"]["text"] and "Prolific ID" in sections["recorded"]["text"]
    assert app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "2026-12-v3"},
                           headers=bearer(token)).status_code == 200
    events = list(csv.DictReader(io.StringIO(app_client.get(
        f"/api/v1/studies/{study_id}/exports/events.csv?include_pilot=true", headers=EXP).text)))
    consent = next(e for e in events if e["kind"] == "consent")
    assert '"consent_version":"2026-12-v3"' in consent["payload"] and '"consent_digest":"' in consent["payload"]
    rows = list(csv.DictReader(io.StringIO(app_client.get(
        f"/api/v1/studies/{study_id}/exports/participants.csv?include_pilot=true", headers=EXP).text)))
    assert rows[0]["consent_version"] == "2026-12-v3"


def test_a_bad_consent_form_field_is_refused_by_name(app_client) -> None:
    from tests.web.conftest import study_spec

    bad = study_spec(["active"], consent_form={"researcher": "x" * 201, "ethics": "ref 1"}, quiz_feedback="yes")
    r = app_client.post("/api/v1/studies", json=bad, headers=EXP)
    assert r.status_code == 422
    fields = {e["field"] for e in r.json()["errors"]}
    assert {"consent_form.researcher", "consent_form.ethics", "quiz_feedback"} <= fields


def _quiz_attempt(client, token: str, answers: dict[str, int]) -> dict:
    r = client.post("/api/v1/me/quiz", json={"answers": answers}, headers=bearer(token))
    assert r.status_code == 200, r.text
    return r.json()


def _to_quiz(client, study_id: str) -> tuple[str, dict]:
    token, state = join(client, study_id)
    client.post("/api/v1/me/consent", json={"agree": True, "consent_version": state["consent"]["version"]},
                headers=bearer(token))
    return token, client.post("/api/v1/me/instructions", headers=bearer(token)).json()


def test_a_failed_quiz_keeps_the_answers_and_names_the_wrong_ones_unless_the_study_hides_them(app_client) -> None:
    shown = make_study(app_client, quiz=QUIZ, quiz_max_attempts=3)
    token, state = _to_quiz(app_client, shown)
    assert state["quiz"]["answers"] == {} and state["quiz"]["wrong"] is None
    after = _quiz_attempt(app_client, token, {"who": 0, "order": 0})["quiz"]
    assert after["answers"] == {"who": 0, "order": 0} and after["wrong"] == ["who"] and after["attempts_left"] == 2

    hidden = make_study(app_client, quiz=QUIZ, quiz_max_attempts=3, quiz_feedback=False)
    token, _ = _to_quiz(app_client, hidden)
    after = _quiz_attempt(app_client, token, {"who": 1, "order": 1})["quiz"]
    assert after["answers"] == {"who": 1, "order": 1} and after["wrong"] is None


def test_the_verdict_records_how_much_of_the_attempt_was_shown_in_the_events_and_steps(app_client) -> None:
    study_id = make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=1)
    token, _ = to_teaching(app_client, study_id)
    demonstrate(app_client, token, ["dinner_plate", "small_plate", "bowl"])
    h = bearer(token)
    for shown in (0.5, None):
        app_client.post("/api/v1/me/execution", headers=h)
        state = app_client.get("/api/v1/me", headers=h).json()
        assert state["execution"]["status"] == "finished" and "motion_seconds" in state["execution"]
        body = {"acceptable": True} if shown is None else {"acceptable": False, "shown_fraction": shown}
        assert app_client.post("/api/v1/me/assessment", json=body, headers=h).status_code == 200
    r = app_client.post("/api/v1/me/assessment", json={"acceptable": True, "shown_fraction": 1.5}, headers=h)
    assert r.status_code == 422 and "shown_fraction" in r.text
    steps = list(csv.DictReader(io.StringIO(app_client.get(
        f"/api/v1/studies/{study_id}/exports/steps.csv?include_pilot=true", headers=EXP).text)))
    assert [(s["step_kind"], s["shown_fraction"], s["replays_watched"]) for s in steps] == [
        ("demonstration", "", ""), ("query", "0.5", "0"), ("test", "", "0")]


def test_a_link_without_a_prolific_id_asks_for_it_unless_the_study_allows_anonymous_participants(app_client) -> None:
    study_id = make_study(app_client)
    asked = app_client.get(f"/study/{study_id}/join?STUDY_ID=s1&SESSION_ID=x1", follow_redirects=False)
    assert asked.status_code == 200 and asked.headers["content-type"].startswith("text/html")
    assert 'name="PROLIFIC_PID"' in asked.text and 'name="SESSION_ID" value="x1"' in asked.text
    joined = app_client.get(f"/study/{study_id}/join?PROLIFIC_PID=p77&STUDY_ID=s1&SESSION_ID=x1",
                            follow_redirects=False)
    assert joined.status_code == 303 and joined.headers["location"].startswith("/p/")

    open_to_all = make_study(app_client, allow_anonymous=True)
    anonymous = app_client.get(f"/study/{open_to_all}/join", follow_redirects=False)
    assert anonymous.status_code == 303
    token = anonymous.headers["location"].rsplit("/", 1)[-1]
    consent = app_client.get("/api/v1/me", headers=bearer(token)).json()["consent"]
    assert consent["anonymous"] is True and consent["allow_anonymous"] is True


def test_attention_signals_are_events_counted_per_participant_and_do_not_postpone_a_time_out(app_client) -> None:
    study_id = make_study(app_client, timeout_minutes=30)
    token, _ = to_teaching(app_client, study_id)
    h = bearer(token)
    before = app_client.get("/api/v1/me", headers=h).json()["idle"]
    assert before["timeout_seconds"] == 1800 and before["idle_seconds"] >= 0
    for kind in ("tab_hidden", "tab_hidden", "window_blur", "paste"):
        assert app_client.post("/api/v1/me/signals", json={"kind": kind}, headers=h).status_code == 204
    assert app_client.post("/api/v1/me/signals", json={"kind": "sneeze"}, headers=h).status_code == 422
    rows = list(csv.DictReader(io.StringIO(app_client.get(
        f"/api/v1/studies/{study_id}/exports/participants.csv?include_pilot=true", headers=EXP).text)))
    assert (rows[0]["tab_hidden"], rows[0]["window_blur"], rows[0]["paste"]) == ("2", "1", "1")
    listed = app_client.get(f"/api/v1/studies/{study_id}/participants", headers=EXP).json()
    assert listed[0]["attention_signals"] == {"tab_hidden": 2, "window_blur": 1, "paste": 1}
    from tableteach.db.tables import ParticipantRow

    ctx = app_client.app.state.context
    with ctx.db.read() as s:
        idle_since = s.get(ParticipantRow, listed[0]["participant_id"]).last_activity_at
    assert app_client.post("/api/v1/me/signals", json={"kind": "window_blur"}, headers=h).status_code == 204
    with ctx.db.read() as s:
        assert s.get(ParticipantRow, listed[0]["participant_id"]).last_activity_at == idle_since
    assert app_client.post("/api/v1/me/signals", json={"kind": "still_here"}, headers=h).status_code == 204
    with ctx.db.read() as s:
        assert s.get(ParticipantRow, listed[0]["participant_id"]).last_activity_at > idle_since


def test_a_withdrawn_participant_is_given_the_way_back_to_the_platform(app_client) -> None:
    study_id = make_study(app_client, completion_url="https://app.example.org/submissions/complete?cc={code}")
    token, _ = to_teaching(app_client, study_id)
    state = app_client.post("/api/v1/me/withdraw", headers=bearer(token)).json()
    assert state["stage"] == "withdrawn" and state["completion"]["return_url"] == "https://app.example.org/"


def test_a_study_with_standard_questionnaires_exports_their_scores_and_cites_them_in_the_codebook(app_client) -> None:
    catalogue = {i["name"]: i for i in app_client.get("/api/v1/instruments", headers=EXP).json()}
    assert set(catalogue) == {"sus", "tlx", "godspeed", "trust"} and "Brooke" in catalogue["sus"]["citation"]
    items = catalogue["sus"]["items"] + catalogue["tlx"]["items"]
    study_id = make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0, questionnaire=items)
    token, _ = to_teaching(app_client, study_id)
    state = demonstrate(app_client, token, ["dinner_plate"])
    assert state["stage"] == "questionnaire" and state["questionnaire"][0]["anchors"] == ["Strongly disagree",
                                                                                         "Strongly agree"]
    answers = {f"sus{n}": 5 if n % 2 else 1 for n in range(1, 11)}
    answers.update({i["id"]: 40 for i in catalogue["tlx"]["items"]})
    r = app_client.post("/api/v1/me/questionnaire", json={"answers": answers}, headers=bearer(token))
    assert r.status_code == 200, r.text
    bad = app_client.post("/api/v1/studies", headers=EXP, json={**_spec(), "questionnaire": [
        {**catalogue["sus"]["items"][0], "instrument_item": "sus99"}]})
    assert bad.status_code == 422 and "questionnaire.0.instrument_item" in bad.text
    rows = list(csv.DictReader(io.StringIO(app_client.get(
        f"/api/v1/studies/{study_id}/exports/scores.csv?include_pilot=true", headers=EXP).text)))
    got = {(r["instrument"], r["scale"]): float(r["score"]) for r in rows}
    assert got[("sus", "sus")] == 100.0 and got[("tlx", "raw_tlx")] == 40.0
    codebook = app_client.get(f"/api/v1/studies/{study_id}/exports/codebook.csv?include_pilot=true", headers=EXP).text
    assert "Hart, S. G., & Staveland" in codebook and "score where instrument = sus" in codebook


def _spec() -> dict:
    from tests.web.conftest import study_spec

    return study_spec(["active"])
