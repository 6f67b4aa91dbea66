"""Issue 11's participant experience on stored executions: notices at each stored action end and the finish,
the event stream waking itself from the stored plan, the study's robot_speed in the stored action times,
"Watch it again" as a replay of the recorded file, and the notifier chosen by the database."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest

from tableteach.robot import ExecutionPlan, TraceRobot
from tableteach.services import ChangeSnapshot, LocalNotifier, executions
from tableteach.web.events import Feeds, stream
from tableteach.web.streams import StreamSlots

from .conftest import EXPERIMENTER_TOKEN, in_process_app
from .helpers import bearer, demonstrate, make_study, to_teaching
from tests.async_run import run_scenario

SECONDS_PER_OBJECT = 0.3


class RecordingTraceRobot(TraceRobot):
    """A trace robot whose executions count as recorded for the browser (as the MuJoCo robot's .viser files)."""

    def plan_execution(self, key: str, events: Sequence[str], name: str, *, speed: float = 1.0) -> ExecutionPlan:
        worked = super().plan_execution(key, events, name, speed=speed)
        return ExecutionPlan(worked.events, worked.trace, worked.action_ends, viewable=True)


@pytest.fixture
def timed_client(tmp_path: Path) -> Iterator[Any]:
    with in_process_app(tmp_path, RecordingTraceRobot("dinner", seconds_per_object=SECONDS_PER_OBJECT)) as client:
        yield client


def _to_first_query(client: Any, **study: Any) -> tuple[str, int]:
    study_id = make_study(client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0, **study)
    token, state = to_teaching(client, study_id)
    demonstrate(client, token, ["dinner_plate", "fork"])
    return token, int(state["participant_id"])


def _stored(client: Any, token: str) -> dict[str, Any]:
    from tableteach.services.state import current_task, participant_and_study

    with client.ctx.db.read() as s:
        participant, _ = participant_and_study(s, token)
        return dict(current_task(s, participant).execution)


def _wait_finished(client: Any, token: str, within: float) -> dict[str, Any]:
    deadline = time.monotonic() + within
    state = client.get("/api/v1/me", headers=bearer(token)).json()
    while state["execution"]["status"] != "finished":
        assert time.monotonic() < deadline, "the execution never finished"
        time.sleep(0.05)
        state = client.get("/api/v1/me", headers=bearer(token)).json()
    return state


class NoticeTimes:
    """Wraps a notifier's publish to note when each notice for one participant came (monotonic seconds)."""

    def __init__(self, notifier: LocalNotifier, pid: int) -> None:
        self.times: list[float] = []
        publish = notifier.publish

        def noted(participant_id: int) -> None:
            if participant_id == pid:
                self.times.append(time.monotonic())
            publish(participant_id)

        notifier.publish = noted  # type: ignore[method-assign]


def _until(condition: Any, what: str, within: float = 60.0) -> None:
    deadline = time.monotonic() + within
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.02)


def test_a_notice_comes_at_each_stored_action_end_and_at_the_finish(timed_client) -> None:
    token, pid = _to_first_query(timed_client)
    notices = NoticeTimes(timed_client.ctx.notifier, pid)
    t0 = time.monotonic()
    started = timed_client.post("/api/v1/me/execution", headers=bearer(token)).json()
    n = len(started["execution"]["events"])
    assert len(notices.times) == 1  # the start, after its commit
    ends = _stored(timed_client, token)["plan"]["action_ends"]
    assert ends == pytest.approx([SECONDS_PER_OBJECT * (i + 1) for i in range(n)])
    _until(lambda: len(notices.times) >= 1 + n, "a stored action end was never announced")
    # Never early: each notice comes at or after its action's stored end (a busy machine only makes them late).
    for end, at in zip(ends, notices.times[1:], strict=False):
        assert at - t0 >= end
    _until(lambda: timed_client.get("/api/v1/me/robot", headers=bearer(token)).json()["moving"] is False,
           "the robot still counts as moving after the last action's end")


def test_the_study_speed_divides_the_stored_action_times(timed_client) -> None:
    token, _pid = _to_first_query(timed_client, robot_speed=2.5)
    started = timed_client.post("/api/v1/me/execution", headers=bearer(token)).json()
    n = len(started["execution"]["events"])
    stored = _stored(timed_client, token)
    assert stored["speed"] == 2.5
    assert stored["plan"]["action_ends"] == pytest.approx([SECONDS_PER_OBJECT / 2.5 * (i + 1) for i in range(n)])
    _wait_finished(timed_client, token, within=60)


def _quiet_counter(notifier, pid: int, quiet: float = 0.3) -> int:
    """The participant's change counter once it has stayed the same for `quiet` seconds."""
    value = notifier.counter(pid)
    while True:
        time.sleep(quiet)
        if notifier.counter(pid) == value:
            return value
        value = notifier.counter(pid)


def test_watch_again_replays_the_recording_in_the_browser_and_the_robot_counts_as_busy(timed_client) -> None:
    token, pid = _to_first_query(timed_client)
    timed_client.post("/api/v1/me/execution", headers=bearer(token))
    _wait_finished(timed_client, token, within=60)
    view = timed_client.post("/api/v1/me/view", headers=bearer(token)).json()
    assert "playbackPath=" in view["url"] and "replay=" not in view["url"]
    notifier = timed_client.ctx.notifier
    before = _quiet_counter(notifier, pid)  # the finish's own notice comes from a timer: let it arrive first

    r = timed_client.post("/api/v1/me/execution/replay", headers=bearer(token))
    assert r.status_code == 200, r.text
    assert r.json()["execution"]["replays"] == 1 and r.json()["execution"]["status"] == "finished"
    assert notifier.counter(pid) == before + 1
    robot = timed_client.get("/api/v1/me/robot", headers=bearer(token)).json()
    assert robot["moving"] and robot["caption"] == executions.REPLAY_CAPTION
    again = timed_client.post("/api/v1/me/view", headers=bearer(token)).json()
    assert again["url"] == view["url"] + "&replay=1"  # a new address: the page reloads the player
    r = timed_client.post("/api/v1/me/execution/replay", headers=bearer(token))
    assert r.status_code == 409 and "being shown again" in r.json()["detail"]

    _until(lambda: notifier.counter(pid) >= before + 2, "the replay's end was never announced")
    _until(lambda: timed_client.get("/api/v1/me/robot", headers=bearer(token)).json()["moving"] is False,
           "the robot still counts as busy after the replay")
    r = timed_client.post("/api/v1/me/assessment", json={"acceptable": True}, headers=bearer(token))
    assert r.status_code == 200, r.text

    from sqlalchemy import select

    from tableteach.db.tables import EventRow
    with timed_client.ctx.db.read() as s:
        kinds = list(s.scalars(select(EventRow.kind).where(EventRow.participant_id == pid).order_by(EventRow.seq)))
    assert kinds.count("replay_watched") == 1 and kinds.index("replay_watched") < kinds.index("assessment")


def test_the_event_stream_wakes_itself_at_the_next_stored_action_end() -> None:
    notifier = LocalNotifier()  # nobody publishes: the process with the timer has gone
    dues = [0.05, None]

    async def read() -> ChangeSnapshot:
        return ChangeSnapshot({"moving": True}, 'W/"state"', dues.pop(0) if dues else None)

    async def scenario() -> list[str]:
        feeds = Feeds(StreamSlots(2, 10))
        opened = feeds.open(5, notifier, read)
        assert opened is not None
        events = stream(feeds, *opened)
        first = await anext(events)
        t0 = time.monotonic()
        second = await asyncio.wait_for(anext(events), 60.0)
        assert time.monotonic() - t0 >= 0.05
        await events.aclose()
        return [first, second]

    first, second = run_scenario(scenario)
    assert first.startswith("retry:") and "event: change" in second
    assert json.loads(second.split("data: ", 1)[1]) == {"n": 0, "robot": {"moving": True}, "state": 'W/"state"'}


def test_on_sqlite_the_notifier_stays_in_the_process(tmp_path: Path) -> None:
    from tableteach.config import Settings
    from tableteach.services import Context

    settings = Settings(database_url=f"sqlite:///{tmp_path / 'n.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                        data_dir=tmp_path / "data")
    ctx = Context.from_settings(settings)
    assert type(ctx.notifier) is LocalNotifier


def test_the_next_stored_action_end_is_told_from_the_database(timed_client) -> None:
    from tableteach import services

    token, _pid = _to_first_query(timed_client)
    assert services.next_robot_change(timed_client.ctx, token) is None  # nothing under way
    timed_client.post("/api/v1/me/execution", headers=bearer(token))
    first = services.next_robot_change(timed_client.ctx, token)
    assert first is not None and 0 < first <= SECONDS_PER_OBJECT
    _wait_finished(timed_client, token, within=60)
    assert services.next_robot_change(timed_client.ctx, token) is None
