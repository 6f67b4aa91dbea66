"""Placements with a robot that takes time (the MuJoCo arm): the request stores the participant's choice and a
settle job and answers at once; the runtime stores the robot's labels when its physics is done, retrying through
a busy database and picking the job up again after a restart; finishing waits for them."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tableteach.robot import Labels

from .conftest import in_process_app
from .helpers import bearer, make_study, to_teaching
from .test_executions import SlowRobot

OBJECTS = ["dinner_plate", "fork", "bowl"]


class GatedRobot(SlowRobot):
    """A robot whose placements wait until the test opens the gate, and that notes the order it placed in."""

    def __init__(self) -> None:
        super().__init__()
        self.release_plans.set()
        self.gate = threading.Event()
        self.gate.set()
        self.at_gate = threading.Event()  # a placement is waiting at the closed gate
        self.order: list[str] = []

    def place(self, key: str, obj: str) -> Labels:
        if not self.gate.is_set():
            self.at_gate.set()
        assert self.gate.wait(60), "the test never opened the gate"
        time.sleep(0.01)  # long enough for a later placement to overtake this one if nothing kept the order
        self.order.append(obj)
        return super().place(key, obj)


@pytest.fixture
def gated(tmp_path: Path) -> Iterator[tuple[Any, GatedRobot]]:
    robot = GatedRobot()
    with in_process_app(tmp_path, robot) as client:
        yield client, robot


def _demonstration(client: Any) -> str:
    study_id = make_study(client, n_practice=0, n_demonstrations=2, n_queries=1, n_tests=0)
    token, _ = to_teaching(client, study_id)
    return token


def _events(client: Any, token: str) -> list[dict[str, Any]]:
    from tableteach.db.analysis_queries import participant_events
    from tableteach.services.state import participant_and_study

    with client.ctx.db.read() as s:
        participant, _ = participant_and_study(s, token)
        return [{"kind": e.kind, **(e.payload or {})} for e in participant_events(s, participant_id=participant.id)]


def _settled(client: Any, token: str, deadline: float = 60.0) -> dict[str, Any]:
    end = time.monotonic() + deadline
    while True:
        state = client.get("/api/v1/me", headers=bearer(token)).json()
        if state["demonstration"]["settled"]:
            return state
        assert time.monotonic() < end, "the robot's labels were never stored"
        time.sleep(0.02)


def test_the_placement_answers_before_the_robot_and_its_labels_follow(gated) -> None:
    client, robot = gated
    token = _demonstration(client)
    robot.gate.clear()
    answer = client.post("/api/v1/me/placements", json={"object": "fork"}, headers=bearer(token))
    assert answer.status_code == 200
    demonstration = answer.json()["demonstration"]
    assert demonstration["placed"] == ["fork"] and not demonstration["settled"]
    assert demonstration["trace"] == []  # nothing reported yet: the settle job stores the cleared table too
    assert [e["kind"] for e in _events(client, token)][-1] == "place"
    robot.gate.set()
    state = _settled(client, token)
    assert state["demonstration"]["trace"] == [[], ["fork"]]
    placed = [e for e in _events(client, token) if e["kind"] == "placed"]
    assert placed == [{"kind": "placed", "object": "fork", "labels": ["fork"], "placed": ["fork"]}]


def test_placements_made_back_to_back_are_placed_in_their_order_and_finishing_waits_for_them(gated) -> None:
    client, robot = gated
    token = _demonstration(client)
    robot.gate.clear()
    threading.Timer(0.3, robot.gate.set).start()  # the robot is still busy when the next requests come
    for obj in OBJECTS:
        assert client.post("/api/v1/me/placements", json={"object": obj}, headers=bearer(token)).status_code == 200
    finished = client.post("/api/v1/me/demonstration/finish", headers=bearer(token))
    assert finished.status_code == 200, finished.text
    assert robot.order == OBJECTS
    events = _events(client, token)
    (demonstration,) = [e for e in events if e["kind"] == "demonstration"]
    assert demonstration["trace"] == [[], ["dinner_plate"], ["dinner_plate", "fork"], ["bowl", "dinner_plate", "fork"]]
    # each placement's labels once, whether the background or the finish stored them
    assert [e["object"] for e in events if e["kind"] == "placed"] == OBJECTS
    time.sleep(0.3)  # a background store that comes late must not touch the next demonstration
    state = client.get("/api/v1/me", headers=bearer(token)).json()
    assert state["step"] == {"kind": "demonstration", "index": 1, "total": 2}
    assert state["demonstration"] == {"placed": [], "labels": [], "trace": [], "settled": True}


def test_a_table_the_robot_lost_is_rebuilt_from_the_stored_placements(gated) -> None:
    client, robot = gated
    token = _demonstration(client)
    client.post("/api/v1/me/placements", json={"object": "dinner_plate"}, headers=bearer(token))
    _settled(client, token)
    for key in list(robot._tables):
        robot.release(key)  # as after a restart, or on another process
    client.post("/api/v1/me/placements", json={"object": "fork"}, headers=bearer(token))
    state = _settled(client, token)
    assert state["demonstration"]["trace"] == [[], ["dinner_plate"], ["dinner_plate", "fork"]]
    assert robot.order == ["dinner_plate", "dinner_plate", "fork"]  # the lost placement was made again first


def test_labels_whose_store_met_a_busy_database_are_stored_once_it_is_free(tmp_path: Path) -> None:
    """The defect that stranded a participant: a label store that got "database busy" was never retried."""
    import sqlite3

    robot = GatedRobot()
    with in_process_app(tmp_path, robot) as client:
        client.ctx.db.busy_seconds = 0.5  # the job's write gives up quickly while the database is held
        token = _demonstration(client)
        robot.gate.clear()
        assert client.post("/api/v1/me/placements", json={"object": "fork"}, headers=bearer(token)).status_code == 200
        failures = client.ctx.runtime.failed_count
        # The job has been claimed and is placing: holding the lock earlier would only keep it from being claimed.
        assert robot.at_gate.wait(60), "the placement's job never reached the robot"
        holder = sqlite3.connect(tmp_path / "app.db", timeout=30)
        holder.execute("BEGIN IMMEDIATE")  # another process holds the write lock
        try:
            robot.gate.set()  # the robot places; storing its labels now meets the held lock
            deadline = time.monotonic() + 60
            while client.ctx.runtime.failed_count == failures and time.monotonic() < deadline:
                time.sleep(0.05)
            assert client.ctx.runtime.failed_count > failures, "the store never met the busy database"
        finally:
            holder.rollback()
            holder.close()
        state = _settled(client, token)  # only the page's own reads: nothing else is needed
        assert state["demonstration"]["trace"] == [[], ["fork"]]


def test_a_placement_acknowledged_before_a_crash_settles_after_the_restart(tmp_path: Path) -> None:
    """The job was stored with the placement: a new process (with a robot that never saw the table) settles it."""
    from tableteach.services.context import Context, default_runtime

    robot = GatedRobot()
    with in_process_app(tmp_path, robot) as client:
        token = _demonstration(client)
        client.ctx.runtime.stop()  # the process dies: nothing runs its jobs any more
        for obj in OBJECTS[:2]:
            assert client.post("/api/v1/me/placements", json={"object": obj}, headers=bearer(token)).status_code == 200
        assert not client.get("/api/v1/me", headers=bearer(token)).json()["demonstration"]["settled"]
        restarted_robot = GatedRobot()
        restarted = Context(client.ctx.db, restarted_robot, client.ctx.settings, notifier=client.ctx.notifier,
                            runtime=default_runtime())
        restarted.runtime.sweep_seconds = 0
        restarted.runtime.start(restarted)
        try:
            state = _settled(client, token)
        finally:
            restarted.runtime.stop()
        assert state["demonstration"]["trace"] == [[], ["dinner_plate"], ["dinner_plate", "fork"]]
        assert restarted_robot.order == OBJECTS[:2]
        assert [e["object"] for e in _events(client, token) if e["kind"] == "placed"] == OBJECTS[:2]
