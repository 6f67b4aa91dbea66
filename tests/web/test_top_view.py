"""GET /api/v1/me/top-view, the participant page's 2D view: the tables from above, then the recorded motion of a
robot execution as compact [x, y, z, yaw] frames; participant-authenticated, and it never writes."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

from tests.waiting import wait_until

from .helpers import bearer, demonstrate, make_study, to_teaching
from .test_viewer import MUJOCO_WAIT_SECONDS, mujoco_client  # noqa: F401 - the fixture

OBJECTS = {"dinner_plate", "small_plate", "bowl", "knife", "fork"}


def database_dump(client: Any) -> list[str]:
    """Every row of the app's SQLite database, as SQL text (to tell that nothing was written)."""
    path = Path(client.ctx.settings.database_url.removeprefix("sqlite:///"))
    with sqlite3.connect(path) as db:
        return list(db.iterdump())


def test_an_unknown_token_is_refused(mujoco_client):  # noqa: F811
    answer = mujoco_client.get("/api/v1/me/top-view", headers=bearer("not-a-token"))
    assert answer.status_code == 401


def test_the_top_view_shows_the_tables_then_the_recorded_execution_and_writes_nothing(mujoco_client):  # noqa: F811
    study_id = make_study(mujoco_client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    token, _state = to_teaching(mujoco_client, study_id)
    h = bearer(token)

    at_demo = mujoco_client.get("/api/v1/me/top-view", headers=h)
    assert at_demo.status_code == 200, at_demo.text
    view = at_demo.json()
    assert {t["name"] for t in view["layout"]["tables"]} == {"Table A", "Table B"}
    assert set(view["layout"]["objects"]) == OBJECTS
    assert all({"start", "slot", "half_x", "half_y"} <= set(o) for o in view["layout"]["objects"].values())
    assert view["motion"] is None and view["step"] is None and not view["pending"]  # a demonstration: no recording

    demonstrate(mujoco_client, token, ["dinner_plate", "bowl"])
    assert mujoco_client.post("/api/v1/me/execution", headers=h).status_code == 200
    view = wait_until(lambda: (v := mujoco_client.get("/api/v1/me/top-view", headers=h).json())["motion"] and v,
                      "the query's recorded motion in the top view", timeout=MUJOCO_WAIT_SECONDS, interval=0.2)
    assert view["step"] == {"task_index": 0, "kind": "query", "index": 0} and not view["pending"]
    motion = view["motion"]
    assert OBJECTS <= set(motion["bodies"]) and "hand" in motion["bodies"]
    assert len(motion["times"]) == len(motion["poses"]) > 10
    assert motion["times"] == sorted(motion["times"])
    assert all(len(frame) == len(motion["bodies"]) and all(len(p) == 4 for p in frame) for frame in motion["poses"])
    # The objects the robot placed end on Table B.
    table_b = next(t for t in view["layout"]["tables"] if t["name"] == "Table B")
    final = dict(zip(motion["bodies"], motion["poses"][-1], strict=True))
    placed = mujoco_client.get("/api/v1/me", headers=h).json()["execution"]["events"]
    for obj in placed:
        x, y = final[obj][:2]
        assert abs(x - table_b["x"]) <= table_b["half_x"] and abs(y - table_b["y"]) <= table_b["half_y"], obj

    before = database_dump(mujoco_client)
    for _ in range(3):
        assert mujoco_client.get("/api/v1/me/top-view", headers=h).status_code == 200
    assert database_dump(mujoco_client) == before
