"""Change notices (LocalNotifier and the server-sent events), the study's robot speed, the page's guidance
(required objects, progress, the lay summary) and "watch again", through the in-process app."""

from __future__ import annotations

import asyncio
import threading

import pytest

from tableteach.core.domain import get_domain
from tableteach.services import TASK_FORMULAS, ChangeSnapshot, LocalNotifier
from tableteach.services.guidance import lay_summary, required_objects
from tableteach.web.events import Feeds, stream
from tableteach.web.streams import StreamSlots
from tableteach.web.viewer import participant_client_html

from .helpers import EXP, bearer, demonstrate, make_study, to_teaching
from tests.async_run import run_scenario
from tests.waiting import WAIT_SECONDS




def test_a_waiter_wakes_on_publish_from_another_thread_and_times_out_otherwise() -> None:
    notifier = LocalNotifier()

    async def scenario() -> tuple[int, int, int]:
        assert await notifier.wait(7, 5, timeout=0.01) == 0  # differs from seen already: at once
        quiet = await notifier.wait(7, 0, timeout=0.05)
        timer = threading.Timer(0.05, notifier.publish, args=(7,))
        timer.start()
        # Its own time-out is far off: only the publish can end this wait (within a generous limit).
        woken = await asyncio.wait_for(notifier.wait(7, 0, timeout=3600.0), WAIT_SECONDS)
        notifier.publish(8)  # another participant's change does not count for 7
        other = await notifier.wait(7, woken, timeout=0.05)
        return quiet, woken, other

    assert run_scenario(scenario) == (0, 1, 1)
    assert notifier.counter(8) == 1 and notifier.counter(9) == 0


def test_the_event_stream_sends_the_counter_then_each_change() -> None:
    notifier = LocalNotifier()

    async def read() -> ChangeSnapshot:
        moved = notifier.counter(3) > 0
        return ChangeSnapshot({"moving": moved}, f'W/"{int(moved)}"', None)

    async def scenario() -> list[str]:
        feeds = Feeds(StreamSlots(2, 10))
        opened = feeds.open(3, notifier, read)
        assert opened is not None
        events = stream(feeds, *opened)
        first = await anext(events)
        asyncio.get_running_loop().call_later(0.05, notifier.publish, 3)
        second = await asyncio.wait_for(anext(events), WAIT_SECONDS)
        await events.aclose()
        assert feeds.feed(3) is None  # the last stream closed: the feed stopped
        return [first, second]

    first, second = run_scenario(scenario)
    assert first.startswith("retry: ")
    assert 'event: change\ndata: {"n":0,"robot":{"moving":false},"state":"W/\\"0\\""}\n\n' in first
    assert second == 'event: change\ndata: {"n":1,"robot":{"moving":true},"state":"W/\\"1\\""}\n\n'


def test_every_stored_action_publishes_a_change_for_that_participant(app_client) -> None:
    token, state = to_teaching(app_client, make_study(app_client, n_practice=0))
    pid = state["participant_id"]
    before = app_client.ctx.notifier.counter(pid)
    r = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token))
    assert r.status_code == 200
    assert app_client.ctx.notifier.counter(pid) == before + 1
    r = app_client.post("/api/v1/me/placements", json={"object": "nonsense"}, headers=bearer(token))
    assert r.status_code == 422 and app_client.ctx.notifier.counter(pid) == before + 1  # nothing stored: no notice


def test_the_events_address_needs_a_known_token(app_client) -> None:
    r = app_client.get("/p/no-such-token/events")
    assert r.status_code == 404 and r.headers["content-type"].startswith("text/html")


def test_state_names_required_objects_progress_and_a_lay_summary(app_client) -> None:
    study = make_study(app_client, n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0,
                       tasks=[{"key": "task2"}])
    token, _ = to_teaching(app_client, study)
    state = app_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["task"]["required"] == ["dinner_plate", "bowl"]
    assert state["progress"]["done"] == 0 and state["progress"]["total"] == 2 and state["progress"]["minutes_left"] >= 1
    demonstrate(app_client, token, ["dinner_plate", "bowl"])
    state = app_client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["stage"] == "questionnaire" and state["progress"]["done"] == 1


def test_the_lay_summary_drops_orders_about_a_forbidden_object_and_merges_chains() -> None:
    space = get_domain("dinner").clause_space
    task1 = lay_summary(space.clauses_of(space.mask_of_formula(TASK_FORMULAS["task1"])))
    assert "dinner plate, then the small plate, then the bowl" in task1 and task1.count("before") == 0
    mask = space.mask_of_formula("F(dinner_plate) & G(!small_plate) & (!small_plate U dinner_plate)")
    text = lay_summary(space.clauses_of(mask))
    assert text == "Place the dinner plate. Never place the small plate."
    assert required_objects({"ground_truth": None}) == []


def test_robot_speed_is_a_study_setting_from_1_to_3(app_client) -> None:
    from .conftest import study_spec

    r = app_client.post("/api/v1/studies", json=study_spec(["active"], robot_speed=2.5), headers=EXP)
    assert r.status_code == 201 and r.json()["robot_speed"] == 2.5
    for bad in (0.5, 4, "fast"):
        r = app_client.post("/api/v1/studies", json=study_spec(["active"], robot_speed=bad), headers=EXP)
        assert r.status_code == 422 and "robot_speed" in r.json()["detail"], bad


def test_watch_again_needs_a_finished_execution(app_client) -> None:
    token, _ = to_teaching(app_client, make_study(app_client, n_practice=0, n_demonstrations=1))
    demonstrate(app_client, token, ["dinner_plate", "bowl"])
    r = app_client.post("/api/v1/me/execution/replay", headers=bearer(token))
    assert r.status_code == 409 and "nothing to watch again" in r.json()["detail"]
    app_client.post("/api/v1/me/execution", headers=bearer(token))
    r = app_client.post("/api/v1/me/execution/replay", headers=bearer(token))
    assert r.status_code == 409 and "no 3D view" in r.json()["detail"]  # the trace robot has no recorded motion


def test_the_participant_copy_of_the_viewer_hides_its_controls_paces_its_frames_and_plays_motions() -> None:
    page = participant_client_html(b"<html><head><title>v</title><script>viser()</script></head><body></body></html>")
    assert b".mantine-Paper-root" in page and page.index(b"tableteach-participant") < page.index(b"<title>")
    # The pacing script runs before viser's own, which it paces (it wraps requestAnimationFrame and setInterval).
    assert page.index(b'<script id="tableteach-pacing">') < page.index(b"<script>viser()")
    assert b"window.requestAnimationFrame =" in page
    # The motion player wraps the Worker that viser's websocket runs in, so it too runs first.
    assert page.index(b'<script id="tableteach-motion">') < page.index(b"<script>viser()")
    assert b"window.Worker = class extends NativeWorker" in page
    with pytest.raises(ValueError, match="<head>"):
        participant_client_html(b"<html><body></body></html>")


def test_progress_follows_the_participants_own_task_order(app_client) -> None:
    study = make_study(app_client, tasks=[{"key": "task1"}, {"key": "task2"}], task_order="balanced",
                       n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0)
    firsts = set()
    for _ in range(2):  # balanced: the second participant does the tasks in the other order
        token, state = to_teaching(app_client, study)
        firsts.add(state["task"]["index"])
        assert state["task"]["position"] == 0
        assert state["progress"]["done"] == 0 and state["progress"]["total"] == 3  # 2 demonstrations, questionnaire
        state = demonstrate(app_client, token, ["dinner_plate", "bowl"])
        assert state["task"]["position"] == 1 and state["progress"]["done"] == 1
    assert firsts == {0, 1}


def test_progress_at_the_quiz_and_after_being_screened_out(app_client) -> None:
    quiz = [{"id": "who", "text": "Who places the objects?", "options": ["I do", "The robot"], "correct": 1}]
    study = make_study(app_client, quiz=quiz, quiz_max_attempts=1, n_practice=0, n_demonstrations=1, n_queries=0,
                       n_tests=0, tasks=[{"key": "task2"}])
    token, state = to_teaching(app_client, study)
    assert state["stage"] == "quiz"
    assert state["progress"]["done"] == 0 and state["progress"]["minutes_left"] >= 1  # nothing done yet
    state = app_client.post("/api/v1/me/quiz", json={"answers": {"who": 0}}, headers=bearer(token)).json()
    assert state["stage"] == "screened_out" and state["progress"]["minutes_left"] == 0


def test_a_timeout_publishes_a_change_so_an_open_page_shows_it(app_client) -> None:
    from datetime import timedelta

    from tableteach import services
    from tableteach.db.tables import ParticipantRow, utcnow

    study = make_study(app_client, timeout_minutes=1)
    token, state = to_teaching(app_client, study)
    pid = state["participant_id"]
    with app_client.ctx.db.write() as s:
        s.get(ParticipantRow, pid).last_activity_at = utcnow() - timedelta(minutes=5)
        s.commit()
    before = app_client.ctx.notifier.counter(pid)
    assert services.expire_timeouts(app_client.ctx, study) == 1
    assert app_client.ctx.notifier.counter(pid) == before + 1


def test_a_refused_resume_on_the_join_link_is_a_plain_page_that_says_what_to_do(app_client) -> None:
    study = make_study(app_client)
    first = app_client.get(f"/study/{study}/join?PROLIFIC_PID=R1", follow_redirects=False)
    assert first.status_code == 303 and "tableteach_browser" in first.headers["set-cookie"]  # the cookie is set
    token = first.headers["location"].rsplit("/", 1)[1]
    app_client.cookies.clear()  # another browser, without the Prolific session id
    r = app_client.get(f"/study/{study}/join?PROLIFIC_PID=R1", follow_redirects=False)
    assert r.status_code == 409 and r.headers["content-type"].startswith("text/html")
    body = r.text.split("<body>")[1]
    assert "already started" in body and "same Prolific session" in body and "not open" not in body
    assert token not in r.text and '"detail"' not in r.text and "set-cookie" not in r.headers
    r = app_client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": "R1"})
    assert r.status_code == 409 and r.json()["state"] is None  # the API keeps JSON


def test_a_bad_robot_speed_in_an_edit_is_named_among_the_field_errors(app_client) -> None:
    from .conftest import study_spec

    study = app_client.post("/api/v1/studies", json=study_spec(["active"]), headers=EXP).json()["id"]
    r = app_client.patch(f"/api/v1/studies/{study}", json={"robot_speed": 5, "n_tests": 99}, headers=EXP)
    assert r.status_code == 422
    assert {e["field"] for e in r.json()["errors"]} >= {"robot_speed", "n_tests"}
    r = app_client.patch(f"/api/v1/studies/{study}", json={"robot_speed": 2}, headers=EXP)
    assert r.status_code == 200 and r.json()["robot_speed"] == 2.0
    assert app_client.get(f"/api/v1/studies/{study}/spec", headers=EXP).json()["robot_speed"] == 2.0


def test_the_codebook_names_every_event_kind_the_services_log() -> None:
    import re
    from pathlib import Path

    from tableteach.services import codebook

    source = "\n".join(p.read_text() for p in Path(codebook.__file__).parent.glob("*.py"))
    logged = set(re.findall(r'\blog\("([a-z_]+)"', source)) | set(re.findall(r'\bkind="([a-z_]+)"', source))
    logged |= set(re.findall(r'end_participation\([^)]*stage="([a-z_]+)"', source))
    assert {"replay_watched", "withdrawn", "screened_out", "execution_finished"} <= logged  # the scan finds them
    levels = {k.split(" (")[0].strip() for k in codebook.MEANINGS["events"]["kind"][2].split(", ")}
    assert logged <= levels, logged - levels


def test_a_stream_whose_feed_fails_before_its_first_read_ends_instead_of_hanging() -> None:
    notifier = LocalNotifier()

    async def read() -> ChangeSnapshot:
        raise RuntimeError("the database is gone")

    async def scenario() -> list[str]:
        feeds = Feeds(StreamSlots(2, 10))
        opened = feeds.open(4, notifier, read)
        assert opened is not None
        return [chunk async for chunk in stream(feeds, *opened)]

    assert run_scenario(scenario) == []  # ended at once: the browser's EventSource reconnects to a new feed
