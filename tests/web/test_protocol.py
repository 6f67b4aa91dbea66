"""The server enforces the protocol: out-of-order or malformed requests get a 4xx that names the problem."""

from __future__ import annotations

from tableteach.config import Settings
from tableteach.db.migrate import upgrade_head
from tableteach.web.app import create_app

from tests.waiting import wait_until

from .conftest import EXPERIMENTER_TOKEN, study_spec
from .helpers import EXP, bearer, demonstrate, join, make_study, to_teaching

ALL = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]


def test_actions_out_of_order_are_409_naming_what_is_expected(app_client) -> None:
    study = make_study(app_client)
    token, state = join(app_client, study)
    h = bearer(token)
    r = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=h)
    assert r.status_code == 409 and "consent stage" in r.json()["detail"]
    r = app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "0"}, headers=h)
    assert r.status_code == 409 and "version" in r.json()["detail"]
    app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=h)
    app_client.post("/api/v1/me/instructions", headers=h)
    r = app_client.post("/api/v1/me/execution", headers=h)
    assert r.status_code == 409 and "practice" in r.json()["detail"] and "query or test" in r.json()["detail"]
    r = app_client.post("/api/v1/me/questionnaire", json={"answers": {}}, headers=h)
    assert r.status_code == 409 and "questionnaire stage" in r.json()["detail"]
    for _ in range(3):
        demonstrate(app_client, token, ALL)
    r = app_client.post("/api/v1/me/assessment", json={"acceptable": True}, headers=h)
    assert r.status_code == 409 and "start its execution first" in r.json()["detail"]
    r = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=h)
    assert r.status_code == 409 and "query 1 of 3" in r.json()["detail"]
    app_client.post("/api/v1/me/execution", headers=h)
    r = app_client.post("/api/v1/me/assessment", json={"acceptable": None}, headers=h)
    assert r.status_code == 422 and "true or false" in r.json()["detail"]


def test_malformed_requests_are_422_naming_the_field(app_client) -> None:
    token, _ = to_teaching(app_client, make_study(app_client))
    h = bearer(token)
    r = app_client.post("/api/v1/me/placements", json={"object": "spoon"}, headers=h)
    assert r.status_code == 422 and r.json()["detail"].startswith("object:")
    r = app_client.post("/api/v1/me/placements", json={"object": "bowl", "colour": "red"}, headers=h)
    assert r.status_code == 422 and "colour" in r.json()["detail"]
    r = app_client.post("/api/v1/me/placements", content=b"{not json",
                        headers={**h, "content-type": "application/json"})
    assert r.status_code == 422
    r = app_client.post("/api/v1/studies", json={"tasks": [{"key": "custom", "ground_truth": "F(spoon)"}]}, headers=EXP)
    assert r.status_code == 422 and "spoon" in r.json()["detail"]
    r = app_client.post("/api/v1/studies", json={"tasks": [{"key": "custom", "ground_truth": "F(bowl) | F(fork)"}]},
                        headers=EXP)
    assert r.status_code == 422 and "template clause" in r.json()["detail"]
    assert app_client.get("/api/v1/studies/nope", headers=EXP).status_code == 404


def test_assessment_waits_for_the_robot_to_finish(tmp_path) -> None:
    from starlette.testclient import TestClient

    # A second per object: the execution is still running when the next request comes, however busy the machine.
    settings = Settings(database_url=f"sqlite:///{tmp_path / 'slow.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                        robot="trace", robot_seconds_per_object=1.0)
    upgrade_head(settings.database_url)
    with TestClient(create_app(settings)) as client:
        token, _ = to_teaching(client, make_study(client, n_practice=0))
        h = bearer(token)
        for _ in range(2):
            demonstrate(client, token, ALL)
        started = client.post("/api/v1/me/execution", headers=h).json()
        assert started["execution"]["status"] == "running" and started["execution"]["events"]
        early = client.post("/api/v1/me/assessment", json={"acceptable": True}, headers=h)
        assert early.status_code == 409 and "still carrying out query 1" in early.json()["detail"]
        state = wait_until(lambda: (me := client.get("/api/v1/me", headers=h).json())["execution"]["status"]
                           == "finished" and me, "the robot to finish the query")
        assert len(state["execution"]["trace"]) == len(state["execution"]["events"]) + 1
        assert client.post("/api/v1/me/assessment", json={"acceptable": True}, headers=h).status_code == 200


def test_questionnaire_completion_code_and_redirect(app_client) -> None:
    study = make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0, conditions=["batch"],
                       completion_url="https://app.prolific.com/submissions/complete?cc={code}")
    token, _ = to_teaching(app_client, study)
    h = bearer(token)
    state = demonstrate(app_client, token, ["dinner_plate", "bowl"])  # stopping early is allowed
    assert state["stage"] == "questionnaire" and [q["id"] for q in state["questionnaire"]] == [
        "learned", "overall", "comments"]
    r = app_client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 6, "overall": 5}}, headers=h)
    assert r.status_code == 422 and "learned" in r.json()["detail"] and "1 to 5" in r.json()["detail"]
    r = app_client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4}}, headers=h)
    assert r.status_code == 422 and "overall" in r.json()["detail"]
    r = app_client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4, "overall": 9, "x": 1}}, headers=h)
    assert r.status_code == 422 and "'x'" in r.json()["detail"]
    done = app_client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4, "overall": 9}}, headers=h).json()
    code = done["completion"]["code"]
    assert done["stage"] == "done" and code
    assert done["completion"]["redirect_url"] == f"https://app.prolific.com/submissions/complete?cc={code}"


def test_join_link_redirects_and_a_repeat_visit_returns_the_same_participant(app_client) -> None:
    study = make_study(app_client)
    link = f"/study/{study}/join?PROLIFIC_PID=p123&STUDY_ID=s9&SESSION_ID=x1"
    first = app_client.get(link, follow_redirects=False)
    second = app_client.get(link, follow_redirects=False)
    assert first.status_code == second.status_code == 303
    assert first.headers["location"] == second.headers["location"] and first.headers["location"].startswith("/p/")
    assert app_client.get(first.headers["location"]).status_code == 200
    other = app_client.get(f"/study/{study}/join?PROLIFIC_PID=p124", follow_redirects=False)
    assert other.headers["location"] != first.headers["location"]
    people = app_client.get(f"/api/v1/studies/{study}/participants", headers=EXP).json()
    assert [p["prolific_pid"] for p in people] == ["p123", "p124"]
    app_client.post(f"/api/v1/studies/{study}/close", headers=EXP)
    assert app_client.get(link, follow_redirects=False).status_code == 303  # returning participant still gets in
    r = app_client.get(f"/study/{study}/join?PROLIFIC_PID=late", follow_redirects=False)
    assert r.status_code == 409 and r.headers["content-type"].startswith("text/html")
    assert "not open" in r.text and "{" not in r.text.split("<body>")[1]  # plain words for a person, no JSON


def test_participant_facing_errors_are_html_pages_and_the_api_keeps_json(app_client) -> None:
    draft = app_client.post("/api/v1/studies", json=study_spec(["active"]), headers=EXP).json()["id"]
    for path, status in ((f"/study/{draft}/join", 409), ("/study/no-such-study/join", 404),
                         ("/study/x/join?PROLIFIC_PID=bad%20id!", 422), ("/p/not-a-token", 404)):
        r = app_client.get(path, follow_redirects=False)
        assert r.status_code == status, path
        assert r.headers["content-type"].startswith("text/html"), path
        assert '"detail"' not in r.text and "<h1>" in r.text and "Prolific" in r.text, path
    r = app_client.post(f"/api/v1/studies/{draft}/join", json={})
    assert r.status_code == 409 and r.json()["detail"].startswith(f"study '{draft}' is draft")


def test_declining_consent_withdraws(app_client) -> None:
    token, _ = join(app_client, make_study(app_client))
    r = app_client.post("/api/v1/me/consent", json={"agree": False, "consent_version": "1"}, headers=bearer(token))
    assert r.json()["stage"] == "withdrawn"
    assert app_client.post("/api/v1/me/instructions", headers=bearer(token)).status_code == 409


def test_balanced_assignment_spreads_conditions(app_client) -> None:
    study = make_study(app_client, conditions=["active", "random", "batch"], assignment="balanced")
    for _ in range(9):
        join(app_client, study)
    people = app_client.get(f"/api/v1/studies/{study}/participants", headers=EXP).json()
    counts = {c: sum(p["condition"] == c for p in people) for c in ("active", "random", "batch")}
    assert counts == {"active": 3, "random": 3, "batch": 3}
    assert all(p["status"] == "active" for p in people)


def test_belief_summary_in_plain_english(app_client) -> None:
    study = make_study(app_client)
    token, _ = to_teaching(app_client, study)
    demonstrate(app_client, token, ALL)
    demonstrate(app_client, token, ALL)
    pid = app_client.get("/api/v1/me", headers=bearer(token)).json()["participant_id"]
    summary = app_client.get(f"/api/v1/studies/{study}/participants/{pid}/belief", headers=EXP).json()
    (task,) = summary["tasks"]
    assert task["n_observations"] == 1 and len(task["top"]) == 5
    assert task["top"][0]["description"].startswith("place the dinner plate")
    assert 0 < task["similarity"] <= 1 and task["entropy"] > 0
    assert app_client.get(f"/api/v1/studies/{study}/participants/999/belief", headers=EXP).status_code == 404
