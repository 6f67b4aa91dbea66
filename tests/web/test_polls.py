"""Cheap polls: GET /me and GET /me/robot carry an ETag; sent back while nothing changed they are answered 304,
and every kind of change (an action, background work, the study, the clock) gives a new tag and the new state."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tableteach.robot import TraceRobot

from .conftest import in_process_app
from .helpers import EXP, bearer, demonstrate, make_study, to_teaching
from .test_executions import SlowRobot, _until


def _poll(client: Any, token: str, path: str, tag: str | None) -> Any:
    headers = bearer(token) | ({"If-None-Match": tag} if tag else {})
    return client.get(path, headers=headers)


def test_an_unchanged_state_is_answered_304_and_a_placement_gives_a_new_tag(app_client) -> None:
    study_id = make_study(app_client, n_practice=0, n_demonstrations=2, n_queries=1, n_tests=0)
    token, _ = to_teaching(app_client, study_id)
    first = _poll(app_client, token, "/api/v1/me", None)
    tag = first.headers["etag"]
    assert first.status_code == 200 and tag.startswith('W/"') and "no-cache" in first.headers["cache-control"]
    again = _poll(app_client, token, "/api/v1/me", tag)
    assert again.status_code == 304 and again.content == b"" and again.headers["etag"] == tag
    assert _poll(app_client, token, "/api/v1/me", f'"other", {tag}').status_code == 304  # a list of tags

    assert app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token)).status_code == 200
    changed = _poll(app_client, token, "/api/v1/me", tag)
    assert changed.status_code == 200 and changed.headers["etag"] != tag
    assert changed.json()["demonstration"]["placed"] == ["bowl"]
    assert _poll(app_client, token, "/api/v1/me", changed.headers["etag"]).status_code == 304


def test_an_actions_answer_carries_the_tag_that_get_me_and_the_change_snapshot_give(app_client) -> None:
    from tableteach import services

    study_id = make_study(app_client, n_practice=0, n_demonstrations=2, n_queries=1, n_tests=0)
    token, _ = to_teaching(app_client, study_id)
    placed = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token))
    tag = placed.json()["etag"]
    assert _poll(app_client, token, "/api/v1/me", tag).status_code == 304  # the page holds it: nothing to read
    assert services.change_snapshot(app_client.ctx, token).state_tag == tag  # a change event now says the same
    full = _poll(app_client, token, "/api/v1/me", None)
    assert full.headers["etag"] == full.json()["etag"] == tag
    app_client.post("/api/v1/me/placements", json={"object": "fork"}, headers=bearer(token))
    assert services.change_snapshot(app_client.ctx, token).state_tag != tag


def test_a_study_edit_gives_a_new_tag(app_client) -> None:
    study_id = make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    token, _ = to_teaching(app_client, study_id)
    tag = _poll(app_client, token, "/api/v1/me", None).headers["etag"]
    edited = app_client.patch(f"/api/v1/studies/{study_id}", json={"timeout_minutes": 45}, headers=EXP)
    assert edited.status_code == 200, edited.text
    changed = _poll(app_client, token, "/api/v1/me", tag)
    assert changed.status_code == 200 and changed.json()["idle"]["timeout_seconds"] == 45 * 60


def test_an_unknown_token_with_a_tag_is_still_refused(app_client) -> None:
    study_id = make_study(app_client)
    token, _ = to_teaching(app_client, study_id)
    tag = _poll(app_client, token, "/api/v1/me", None).headers["etag"]
    assert _poll(app_client, "not-a-token", "/api/v1/me", tag).status_code == 401
    assert _poll(app_client, "not-a-token", "/api/v1/me/robot", "*").status_code == 401


def test_a_plan_stored_by_background_work_gives_a_new_tag(tmp_path: Path) -> None:
    """The plan is stored by a job, with no action of the participant: the tag must change all the same."""
    robot = SlowRobot()
    with in_process_app(tmp_path, robot) as client:
        study_id = make_study(client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
        token, _ = to_teaching(client, study_id)
        demonstrate(client, token, ["dinner_plate", "fork"])
        assert client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
        waiting = _poll(client, token, "/api/v1/me", None)
        tag = waiting.headers["etag"]
        assert waiting.json()["execution"]["motion_seconds"] == 0  # no plan yet
        assert _poll(client, token, "/api/v1/me", tag).status_code == 304
        robot.release_plans.set()
        seen: dict[str, Any] = {}

        def planned() -> bool:
            answer = _poll(client, token, "/api/v1/me", tag)
            if answer.status_code == 200:
                seen.update(answer.json())
            return bool(seen.get("execution", {}).get("motion_seconds"))

        _until(planned, "no poll ever showed the plan stored by the work_out job")


def test_the_clock_alone_changes_the_tag_when_an_execution_reaches_its_stored_end() -> None:
    """Between the stored end and the runtime's record of the finish nothing is written, yet the page must see
    the execution finished: the tag includes it."""
    from datetime import timedelta

    from tableteach.db.repository import PollRow
    from tableteach.db.tables import utcnow
    from tableteach.services.freshness import state_tag

    edited = utcnow()

    def row(started_seconds_ago: float) -> PollRow:
        execution = {"status": "running", "events": ["fork"], "started_at":
                     (utcnow() - timedelta(seconds=started_seconds_ago)).isoformat(),
                     "plan": {"action_ends": [5.0], "trace": [[], ["fork"]]}}
        return PollRow(1, 3, "task", 0, edited, 2, execution)

    assert state_tag(row(1.0)) == state_tag(row(2.0))  # still running: the same tag
    assert state_tag(row(1.0)) != state_tag(row(6.0))  # past its stored end


def test_the_robot_activity_is_answered_304_until_it_changes(tmp_path: Path) -> None:
    robot = TraceRobot("dinner", seconds_per_object=0.05)
    with in_process_app(tmp_path, robot) as client:
        study_id = make_study(client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
        token, _ = to_teaching(client, study_id)
        first = _poll(client, token, "/api/v1/me/robot", None)
        tag = first.headers["etag"]
        assert first.status_code == 200 and not first.json()["moving"]
        assert _poll(client, token, "/api/v1/me/robot", tag).status_code == 304
        demonstrate(client, token, ["dinner_plate", "fork"])
        assert client.post("/api/v1/me/execution", headers=bearer(token)).status_code == 200
        busy = _poll(client, token, "/api/v1/me/robot", tag)
        assert busy.status_code == 200 and busy.json()["moving"] and busy.headers["etag"] != tag
