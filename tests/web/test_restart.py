"""Killing the server mid-session loses nothing acknowledged: the participant continues where they were,
with the same belief and the same next query."""

from __future__ import annotations

from tests.states import comparable

import sqlite3

import pytest

from tableteach.client import ExperimenterClient, ParticipantClient, run_teacher
from tableteach.core import session as core

from tests.waiting import wait_until

from .conftest import EXPERIMENTER_TOKEN, open_study, study_spec

pytestmark = pytest.mark.slow


def _stored_state(db_path: str, participant_id: int) -> core.SessionState:
    with sqlite3.connect(db_path) as con:
        (text,) = con.execute("select state_json from task_sessions where participant_id = ? order by task_index desc",
                              (participant_id,)).fetchone()
    return core.SessionState.from_json(text)


def _belief(url: str, study_id: str, participant_id: int) -> dict:
    exp = ExperimenterClient(url, token=EXPERIMENTER_TOKEN)
    try:
        return exp.belief(study_id, participant_id)
    finally:
        exp.close()


def test_kill_before_a_query_then_same_query_after_restart(server_factory) -> None:
    first = server_factory()
    study_id = open_study(first.url, study_spec(["active"]))
    # consent, instructions, practice, 2 demonstrations: the next step is the first query.
    run = run_teacher(first.url, study_id, ["task1"], seed=11, stop_after=5)
    api = ParticipantClient(first.url, token=run.token)
    before = api.state()
    assert (before["step"]["kind"], before["execution"]["status"]) == ("query", "not_started")
    belief_before = _belief(first.url, study_id, run.participant_id)
    expected = core.next_step(_stored_state(str(first.db_path), run.participant_id)).robot_execution.events
    api.close()
    first.kill()

    second = server_factory()
    api = ParticipantClient(second.url, token=run.token)
    after = api.state()
    assert comparable(after) == comparable(before)
    assert _belief(second.url, study_id, run.participant_id) == belief_before
    started = api.execute({"task_index": 0, "step_kind": "query", "step_index": 0})
    assert tuple(started["execution"]["events"]) == expected
    finished = run_teacher(second.url, study_id, ["task1"], seed=11, client=api)
    assert finished.completion_code is not None


def test_kill_while_the_robot_executes_and_mid_demonstration(server_factory) -> None:
    slow = {"TABLETEACH_ROBOT_SECONDS_PER_OBJECT": "0.4"}
    first = server_factory(**slow)
    study_id = open_study(first.url, study_spec(["active"]))
    run = run_teacher(first.url, study_id, ["task1"], seed=5, stop_after=5)
    api = ParticipantClient(first.url, token=run.token)
    running = api.execute()
    assert running["execution"]["status"] == "running"
    events = running["execution"]["events"]
    first.kill()

    second = server_factory(**slow)
    api = ParticipantClient(second.url, token=run.token)
    state = api.state()
    assert state["execution"]["events"] == events and state["step"] == running["step"]
    # The robot forgot the execution with the old process; it carries out the same one again.
    state = wait_until(lambda: (s := api.state())["execution"]["status"] == "finished" and s,
                       "the restarted server to finish the execution", interval=0.1)
    assert state["execution"]["events"] == events
    second.kill()

    # Mid-demonstration: with two objects placed, a crash keeps them; the third placement continues the trace.
    third = server_factory()
    study2 = open_study(third.url, study_spec(["active"]))
    api = ParticipantClient(third.url)
    state = api.join(study2)["state"]
    api.consent(state["consent"]["version"])
    api.instructions()
    api.place("dinner_plate")
    placed = api.place("fork")
    third.kill()
    fourth = server_factory()
    api = ParticipantClient(fourth.url, token=api.token)
    assert api.state()["demonstration"] == placed["demonstration"]
    state = api.place("knife")
    assert state["demonstration"]["placed"] == ["dinner_plate", "fork", "knife"]
    assert state["demonstration"]["trace"] == [[], ["dinner_plate"], ["dinner_plate", "fork"],
                                               ["dinner_plate", "fork", "knife"]]
    finished = run_teacher(fourth.url, study2, ["task1"], seed=2, client=api)
    assert finished.completion_code is not None

