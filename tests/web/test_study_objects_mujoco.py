"""A study with its own objects taught to completion over REST against a server with the MuJoCo robot: the robot
carries the study's objects in its generated scene, and MuJoCo's labels are what the server records."""

from __future__ import annotations

from typing import Any

import httpx

from .conftest import EXPERIMENTER_TOKEN
from .test_study_objects import NAMES, _teach
from ..study_objects import lunch_study

MUJOCO = {"TABLETEACH_ROBOT": "mujoco", "TABLETEACH_ROBOT_SPEED": "8", "TABLETEACH_ROBOT_WORKERS": "1"}


def test_a_study_with_its_own_objects_runs_to_completion_with_the_mujoco_robot(server_factory: Any) -> None:
    server = server_factory(**MUJOCO)
    exp = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}
    with httpx.Client(base_url=server.url, timeout=120) as client:
        created = client.post("/api/v1/studies", json=lunch_study(), headers=exp)
        assert created.status_code == 201, created.text
        study_id = created.json()["id"]
        assert client.post(f"/api/v1/studies/{study_id}/open", headers=exp).status_code == 200
        token, done = _teach(client, study_id)
        assert done["stage"] == "done"
        top = client.get("/api/v1/me/top-view", headers={"Authorization": f"Bearer {token}"}).json()
        assert list(top["layout"]["objects"]) == NAMES
        mug = top["layout"]["objects"]["mug"]
        assert mug["colour"] == "#2e86c1" and mug["kind"] == "cup"
        # The slot the layout reports is the one the definition gives: x right of Table B's centre, y towards the robot.
        assert (round(mug["slot"]["x"], 3), round(mug["slot"]["y"], 3)) == (0.45 - 0.10, -0.33 + 0.13)
        events = client.get(f"/api/v1/studies/{study_id}/exports/events.csv", headers=exp).text
        placed = [line for line in events.splitlines() if ",placed," in line]
        assert len(placed) == 3 and all("lunch_box" in line for line in placed)  # MuJoCo's labels, box first
        replay = client.get(f"/api/v1/studies/{study_id}/participants/1/replays/0/query/0", headers=exp)
        assert replay.status_code == 200, replay.text
        assert replay.json()["source"] == "recording" and set(replay.json()["layout"]["objects"]) == set(NAMES)
        assert set(replay.json()["recording"]["bodies"]) >= set(replay.json()["objects"])
